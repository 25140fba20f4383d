"""Every group of every kind of file smd writes opens whole in xarray (h5netcdf), every axis named by a dimension
scale: no phony dimensions, no axis named twice, nothing xarray refuses."""

from __future__ import annotations

import warnings

import h5py
import numpy as np
import pytest
import xarray as xr

from conftest import SCENARIOS, chain_files

from smdcli.model.sparse import SPARSE_DOFS

RECORD = SCENARIOS.parent / "records" / "synthetic_20s_100hz.csv"


def _runs():
    """(name, smd arguments, file written) of every kind of result file."""
    return [
        ("simulate, forced", ["simulate", SCENARIOS / "three_dof_forced.toml"], "three_dof_forced.h5"),
        ("simulate, [system] matrices", ["simulate", SCENARIOS / "three_dof_matrix_forced.toml"],
         "three_dof_matrix_forced.h5"),
        ("simulate, ground record", ["simulate", SCENARIOS / "shear_frame_record.toml"], "shear_frame_record.h5"),
        ("simulate, yield and events", ["simulate", SCENARIOS / "shear_frame_bilinear.toml"],
         "shear_frame_bilinear.h5"),
        ("simulate, friction", ["simulate", SCENARIOS / "friction_isolated_building.toml"],
         "friction_isolated_building.h5"),
        ("simulate, Bouc-Wen", ["simulate", SCENARIOS / "bouc_wen_multisine.toml"], "bouc_wen_multisine.h5"),
        ("simulate, stop", ["simulate", SCENARIOS / "bouncing_ball.toml"], "bouncing_ball.h5"),
        ("sweep, parameter grid", ["sweep", SCENARIOS / "one_dof_regimes_sweep.toml"], "one_dof_regimes_sweep_sweep.h5"),
        ("sweep, full histories", ["sweep", SCENARIOS / "one_dof_underdamped.toml", "--param", "damper[0].c",
                                   "--values", "0.5,1", "--keep", "full"], "one_dof_underdamped_sweep.h5"),
        ("sweep, each member its own times", ["sweep", SCENARIOS / "one_dof_underdamped.toml", "--param", "time.end",
                                              "--values", "1,2", "--keep", "full"], "one_dof_underdamped_sweep.h5"),
        ("sweep, initial conditions", ["sweep", SCENARIOS / "ic_underdamped.toml"], "ic_underdamped_sweep.h5"),
        ("sweep, frequency response", ["sweep", SCENARIOS / "frequency_response_zeta.toml"],
         "frequency_response_zeta_sweep.h5"),
        ("sweep, measured response", ["sweep", SCENARIOS / "duffing_frequency_response.toml"],
         "duffing_frequency_response_sweep.h5"),
        ("sweep, transmissibility", ["sweep", SCENARIOS / "transmissibility_1dof.toml"],
         "transmissibility_1dof_sweep.h5"),
        ("spectrum", ["spectrum", RECORD, "--periods", "0.1:2:5"], "synthetic_20s_100hz_spectrum.h5"),
        ("shock spectrum", ["spectrum", RECORD, "--kind", "srs", "--frequencies", "1,5,10", "--q", "10,20"],
         "synthetic_20s_100hz_srs.h5"),
        ("inelastic spectrum", ["spectrum", RECORD, "--periods", "0.2,0.5,1", "--damping", "0.02,0.05",
                                "--ductility", "1,2,4"], "synthetic_20s_100hz_spectrum.h5"),
        ("processed record", ["record", RECORD, "--baseline", "linear", "--filter", "0.1,25"],
         "synthetic_20s_100hz_record.h5"),
        ("random vibration", ["psd", SCENARIOS / "component_random_vibration.toml", "--input",
                              RECORD.parent / "navmat_p9492_profile.csv"], "component_random_vibration_psd.h5"),
        ("random vibration, white noise on a force", ["psd", SCENARIOS / "two_dof_forced.toml", "--input", "white:2",
                                                      "--on", "m1"], "two_dof_forced_psd.h5"),
        ("response-spectrum analysis", ["rsa", SCENARIOS / "five_storey_building.toml", "--spectrum",
                                        RECORD.parent / "design_spectrum_sds1_sd06.csv"], "five_storey_building_rsa.h5"),
        ("compare-solvers", ["compare-solvers", SCENARIOS / "one_dof_underdamped.toml", "--methods", "RK45,rk4",
                             "--tolerances", "1e-4,1e-6", "--steps", "0.05,0.01", "--repeats", "1"],
         "one_dof_underdamped_compare.h5"),
        ("phase", ["phase", SCENARIOS / "two_dof_forced.toml"], "two_dof_forced_portrait.h5"),
        ("phase, Poincare", ["phase", SCENARIOS / "one_dof_harmonic.toml", "--poincare", "--name", "poincare"],
         "poincare_portrait.h5"),
        ("phase, hysteresis", ["phase", SCENARIOS / "elastoplastic_record.toml", "--hysteresis"],
         "elastoplastic_record_hysteresis.h5"),
    ]


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """Each kind of file, written once by the CLI."""
    from smdcli.cli import run as smd

    files = {}
    big = chain_files(tmp_path_factory.mktemp("matrices"), SPARSE_DOFS + 10, step=0.1)
    for i, (name, args, produced) in enumerate(_runs() + [SPARSE_RUN]):
        out = tmp_path_factory.mktemp(f"kind{i}")
        args = [big if a == SPARSE_CHAIN else a for a in args]
        plots = ["--no-plots"] if args[0] != "phase" else []  # phase writes its portrait always
        assert smd([str(a) for a in args] + ["-o", str(out), "--quiet", *plots]) == 0, name
        files[name] = out / produced
    return files


def _groups(path):
    names = ["/"]
    with h5py.File(path) as f:
        f.visititems(lambda name, obj: names.append("/" + name) if isinstance(obj, h5py.Group) else None)
    return names


def _unnamed_axes(path):
    """Data sets with an axis that has no dimension scale attached (scales themselves name their own axis)."""
    bare = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.ndim and not obj.is_scale:
            bare.extend(f"/{name} axis {axis}" for axis in range(obj.ndim) if not len(obj.dims[axis]))
    with h5py.File(path) as f:
        f.visititems(visit)
    return bare


# a sparse scene from Matrix Market files: its M, C, K written as their nonzero entries
SPARSE_CHAIN = "<a chain of SPARSE_DOFS + 10 masses, M, C, K in .mtx files>"
SPARSE_RUN = ("simulate, sparse [system] from files", ["simulate", SPARSE_CHAIN], "chain.h5")
KINDS = [name for name, _, _ in _runs()] + [SPARSE_RUN[0]]


@pytest.mark.parametrize("kind", KINDS)
def test_every_axis_of_every_data_set_has_a_named_scale(written, kind):
    assert _unnamed_axes(written[kind]) == []


@pytest.mark.parametrize("kind", KINDS)
def test_every_group_opens_whole_in_xarray_without_phony_dimensions(written, kind):
    path = written[kind]
    for group in _groups(path):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # "Duplicate dimension names" and phony_dims notices fail
            with xr.open_dataset(path, engine="h5netcdf", group=group, phony_dims=None) as ds:
                ds.load()
                assert not [d for d in ds.sizes if str(d).startswith("phony")], group
                for var in ds.variables.values():
                    assert len(set(var.dims)) == len(var.dims), (group, var.name)


def test_xarray_reads_the_numbers_h5py_reads(written):
    path = written["simulate, yield and events"]
    with h5py.File(path) as f:
        drift = f["displacement"][()]
        K, events = f["model/K"][()], f["events/time"][()]
        springs = f["elements/spring_force"][()]
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert ds["displacement"].dims == ("time", "dof")
        assert np.array_equal(ds["displacement"].values, drift)
    with xr.open_dataset(path, engine="h5netcdf", group="model") as ds:
        assert ds["K"].dims == ("dof_row", "dof_col")
        assert list(ds["dof_row"].values) == list(ds["dof_col"].values)
        assert np.array_equal(ds["K"].values, K)
    with xr.open_dataset(path, engine="h5netcdf", group="events") as ds:
        assert np.array_equal(ds["time"].values, events)
    with xr.open_dataset(path, engine="h5netcdf", group="elements") as ds:
        assert ds["spring_force"].dims == ("time", "spring")
        assert np.array_equal(ds["spring_force"].values, springs)
