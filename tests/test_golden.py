"""Golden outputs: every bundled scenario's HDF5, regenerated and compared with `smd diff` semantics,
and every golden checked against an independent reference so that none can enshrine a bug.

After an intended change: `python tests/golden/bless.py` (or with stems), then this file."""

import functools
import sys

import h5py
import numpy as np
import pytest
from conftest import ROOT, SCENARIOS

from smdcli import scenario
from smdcli.commands.diff import diff, format_report
from smdcli.model import build
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

sys.path.insert(0, str(ROOT / "tests" / "golden"))
import bless  # noqa: E402

GOLDEN = ROOT / "tests" / "golden"
SIMULATE = bless.golden_names()
SWEEPS = bless.sweeps()


def test_every_scenario_has_a_golden():
    assert sorted(p.stem for p in GOLDEN.glob("*.h5")) == SIMULATE
    assert sorted(p.stem for p in (GOLDEN / "sweep").glob("*.h5")) == SWEEPS


@pytest.mark.parametrize("stem, kind", [(s, "simulate") for s in SIMULATE] + [(s, "sweep") for s in SWEEPS])
def test_regenerated_output_matches_the_golden(stem, kind, tmp_path):
    golden = bless.golden_path(stem, kind)
    full = bless.regenerate(stem, tmp_path / "full", kind)
    with h5py.File(golden) as f:
        stride = int(f.attrs["golden_stride"])
    fresh = tmp_path / golden.name
    bless.downsample(full, fresh, stride)
    # Within what the two runs state of their own accuracy, not bitwise: another CPU's BLAS rounds otherwise.
    report = diff(golden, fresh, stated=True)
    assert not report.differs, format_report(report)
    with h5py.File(golden) as g, h5py.File(full) as f:
        if "time" in f:  # the kept times span the whole run
            assert g["time"][()].ravel()[-1] == f["time"][()].ravel()[-1] or stride == 1 or \
                f["time"][()].ravel()[-1] - g["time"][()].ravel()[-1] < stride * np.diff(f["time"][()].ravel()[:2])[0]


@functools.lru_cache(maxsize=None)
def _reference(stem: str, golden_method: str):
    sc = scenario.load(SCENARIOS / f"{stem}.toml")
    model = build(sc)
    with h5py.File(GOLDEN / f"{stem}.h5") as f:
        grid = f["time"][()]
    return reference(sc, model, grid, golden_method)


def reference(sc, model, grid, golden_method: str = ""):
    """A different method, much tighter: DOP853 at rtol 1e-12, or Radau at 1e-10 for a nonlinear or stiff scene
    (DOP853 at 1e-11 where Radau wrote the golden, and on a scene linear between events: each piece is smooth and
    not stiff, and DOP853 locates the events on its interpolant 7 times faster than Radau; Radau where DOP853 wrote
    it)."""
    implicit = (not model.is_linear and not model.is_piecewise_linear) or model.is_stiff
    method, rtol = ("Radau", 1e-10) if implicit else ("DOP853", 1e-12)
    if method == golden_method or model.is_piecewise_linear:
        method, rtol = "DOP853", 1e-11
    if method == golden_method:  # DOP853 wrote it (a linear scene with a force that has no exact integral)
        method, rtol = "Radau", 1e-10
    scale = max(np.abs(model.x0).max(initial=0.0), 1e-3)
    return solve(model, grid, method, Tolerances(rtol=rtol, atol=rtol * 1e-3 * scale)), method


@pytest.mark.parametrize("stem", SIMULATE)
def test_golden_against_an_independent_reference(stem):
    golden = GOLDEN / f"{stem}.h5"
    with h5py.File(golden) as f:
        stored = f["displacement"][()]
        method = f["solver"].attrs["method"]
    ref, ref_method = _reference(stem, method)
    assert ref.success and ref_method != method
    peak = np.abs(ref.displacement).max()
    if peak == 0:  # a scene at rest (an initial-condition study's base scene): nothing may move
        assert not stored.any()
        return
    error = np.abs(stored - ref.displacement).max() / peak
    print(f"{stem}: {method} golden against {ref_method}: {error:.2e} of the peak")
    exact = method in ("exact", "closed_form")
    assert error < (1e-8 if exact else 2e-5), f"{stem}: {method} golden vs {ref_method}: {error:.2e}"


@pytest.mark.parametrize("stem", SWEEPS)
def test_sweep_golden_against_an_independent_reference(stem):
    """Time families against a tight DOP853 run of each member; frequency responses against a direct
    complex solve of (K - w^2 M + i w C) x = b at every stored frequency."""
    golden = bless.golden_path(stem, "sweep")
    sc = scenario.load(SCENARIOS / f"{stem}.toml")
    from smdcli.sweep import build_family, read_spec

    family = build_family(sc, read_spec(sc, {}))
    with h5py.File(golden) as f:
        if "frequency" in f:
            omega, amplitude = f["frequency"][()], f["amplitude"][()]
            if f.attrs["input_dof"] == "ground":  # transmissibility: X = 1 U + Y, Z Y = w^2 M 1 U
                forces = f["force_transmissibility"][()]
                for s in range(len(family)):
                    M, C, K = family.M[s], family.C[s], family.K[s]
                    ones = np.ones(len(M))
                    for i, w in enumerate(omega):
                        Y = np.linalg.solve(K - w**2 * M + 1j * w * C, w**2 * M @ ones)
                        np.testing.assert_allclose(amplitude[s, i], np.abs(1 + Y), rtol=1e-10)
                        np.testing.assert_allclose(forces[s, i], abs((K @ ones + 1j * w * C @ ones) @ Y) /
                                                   (ones @ K @ ones), rtol=1e-10)
                return
            dof = list(family.base.dofs).index(f.attrs["input_dof"])
            for s in range(len(family)):
                b = np.zeros(family.base.n)
                b[dof] = 1.0
                for i, w in enumerate(omega):
                    Z = family.K[s] - w**2 * family.M[s] + 1j * w * family.C[s]
                    if abs(np.linalg.det(Z)) == 0:
                        assert np.isinf(amplitude[s, i]).all()
                        continue
                    direct = np.abs(np.linalg.solve(Z, b))
                    np.testing.assert_allclose(amplitude[s, i], direct, rtol=1e-10)
            return
        grid, stored = f["time"][()], f["displacement"][()]
    for s in range(len(family)):
        ref = solve(family.model(s), grid, "DOP853", Tolerances(rtol=1e-12, atol=1e-16))
        error = np.abs(stored[s] - ref.displacement).max() / np.abs(ref.displacement).max()
        assert error < 1e-8, f"{stem} member {s}: {error:.2e}"


@pytest.mark.parametrize("stem", SIMULATE)
def test_stated_accuracy_is_honest_and_catches_real_changes(stem, tmp_path):
    """Each golden's stated accuracy covers its true error (the independent reference above), and a change
    of ten times the stated accuracy of the peak is reported by `smd diff --tolerance stated`."""
    golden = GOLDEN / f"{stem}.h5"
    with h5py.File(golden) as f:
        stored = f["displacement"][()]
        stated = float(f["displacement"].attrs["stated_accuracy"])
        method = f["solver"].attrs["method"]
    ref, _ = _reference(stem, method)  # the one the test above used, solved once
    peak = np.abs(ref.displacement).max()
    assert 0 < stated < 0.1
    if peak > 0:
        error = np.abs(stored - ref.displacement).max() / peak
        reference_error = {"Radau": 1e-10, "DOP853": 1e-12}.get(ref.stats.method, 1e-11)
        reference_error = 1e-11 if ref.stats.rtol == 1e-11 else reference_error  # the reference's own tolerance
        assert error <= stated + 100 * reference_error, f"{stem}: error {error:.2e} > stated {stated:.2e}"
    changed = tmp_path / "changed.h5"
    changed.write_bytes(golden.read_bytes())
    with h5py.File(changed, "r+") as f:
        data = f["displacement"][()]
        scale = max(np.abs(data).max(), 1e-300)
        data.flat[len(data.flat) // 2] += 10 * stated * scale
        f["displacement"][...] = data
    report = diff(golden, changed, stated=True)
    assert report.differs and [d.name for d in report.datasets if d.status != "same"] == ["displacement"]


@pytest.mark.parametrize("stem, method", [("three_dof_forced", None), ("one_dof_nonlinear_stiff", None),
                                          ("two_dof_forced", "newmark"), ("two_dof_forced", "ode23s")])
def test_outputs_are_bitwise_deterministic(cli, tmp_path, stem, method):
    extra = ["--method", method] if method else []
    for out in ("a", "b"):
        result = cli("simulate", SCENARIOS / f"{stem}.toml", "-o", tmp_path / out, "--no-plots", *extra)
        assert result.exit_code == 0, result.output
    report = diff(tmp_path / "a" / f"{stem}.h5", tmp_path / "b" / f"{stem}.h5", rtol=0.0, atol=0.0)
    assert not report.differs, format_report(report)
    with h5py.File(tmp_path / "a" / f"{stem}.h5") as f:
        assert "created" in f.attrs and "wall_time_s" in f["solver"].attrs  # present, and ignored by diff
