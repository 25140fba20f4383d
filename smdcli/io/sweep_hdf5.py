"""HDF5 layout of a sweep: members on a leading axis, the grid's axes, stacked results or a frequency response.

Must not import: commands, cli."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.io.atomic import atomic_path
from smdcli.io.hdf5 import _strings, write_header, write_matrices
from smdcli.solvers.base import acceleration_accuracy
from smdcli.sweep.spec import METRIC_UNITS, SETTLING_BAND, parameter_units


def write_sweep(path: Path, family, result=None, metrics=None, response=None, run: dict | None = None) -> None:
    """Write a sweep: members on a leading axis (a dimension scale), the swept values, stacked results or a frequency response."""
    import h5py


    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_header(f, family.scenario, "sweep")
        spec = family.spec
        f.attrs["sweep_kind"] = spec.kind
        f.attrs["parameters"] = list(spec.parameters)
        f.attrs["grid_shape"] = list(family.shape)
        S = len(family)
        member = f.create_dataset("member", data=np.arange(S))
        member.make_scale("member")
        _strings(f, "label", family.labels).dims[0].attach_scale(member)
        params = f.create_group("parameters")
        grid = f.create_group("grid") if spec.parameters else None
        if grid is not None:
            grid.attrs["grid_shape"] = list(family.shape)
            grid.attrs["order"] = "C: the last parameter varies fastest along member"
        for i, name in enumerate(spec.parameters):
            ds = params.create_dataset(name, data=family.values[:, i])
            ds.attrs["units"] = parameter_units(name)
            ds.dims[0].attach_scale(member)
            # The grid's own axis: member reshapes to grid_shape, and these are its coordinates.
            axis = grid.create_dataset(name, data=np.asarray(spec.values[i], dtype=float))
            axis.attrs["units"] = parameter_units(name)
            axis.attrs["axis"] = i
            axis.make_scale(name)
        dof = _strings(f, "dof", family.base.dofs)
        dof.make_scale("dof")
        initial = f.create_group("initial_conditions")
        for name in ("x0", "v0"):
            ds = initial.create_dataset(name, data=getattr(family, name))
            ds.dims[0].attach_scale(member)
            ds.dims[1].attach_scale(dof)
        model = f.create_group("model")
        write_matrices(model, family, dof, member)
        if run:
            group = f.create_group("run")
            for key, value in run.items():
                group.attrs[key] = value
        if result is not None:
            _write_time_family(f, family, result, metrics, member, dof)
        if response is not None:
            _write_response(f, response, member, dof, family, spec.normalized)


def _write_time_family(f, family, result, metrics, member, dof) -> None:
    time = f.create_dataset("time", data=result.time)
    time.attrs["units"] = "s"
    if result.time.ndim == 1:
        time.make_scale("time")
    for name, units in (("displacement", "m"), ("velocity", "m/s"), ("acceleration", "m/s^2"), ("force", "N")):
        ds = f.create_dataset(name, data=np.ascontiguousarray(getattr(result, name)))
        ds.attrs["units"] = units
        if result.stated_accuracy is not None and name != "force":  # the worst member's, relative to the peak
            stated = float(np.nanmax(result.stated_accuracy, initial=0.0))
            if name == "acceleration":
                stated = float(np.nanmax(acceleration_accuracy(
                    family.M, family.C, family.K, result.stated_accuracy, result.displacement, result.velocity,
                    result.acceleration, result.force), initial=0.0))
            ds.attrs["stated_accuracy"] = stated
        ds.dims[0].attach_scale(member)
        if result.time.ndim == 1:
            ds.dims[1].attach_scale(time)
        ds.dims[2].attach_scale(dof)
    f.create_dataset("success", data=result.success).dims[0].attach_scale(member)
    _strings(f, "message", result.messages).dims[0].attach_scale(member)
    _strings(f, "method", result.methods).dims[0].attach_scale(member)

    if result.stated_accuracy is not None:
        ds = f.create_dataset("stated_accuracy", data=result.stated_accuracy)
        ds.attrs["units"] = "1"
        ds.attrs["meaning"] = "each member's vouched error, relative to its peak"
        ds.dims[0].attach_scale(member)
    group = f.create_group("metrics")
    group.attrs["settling_band"] = SETTLING_BAND
    for name, values in metrics.items():
        ds = group.create_dataset(name, data=values)
        ds.attrs["units"] = METRIC_UNITS[name]
        if name != "settling_time" and result.stated_accuracy is not None:  # peaks and RMS carry the runs' error
            ds.attrs["stated_accuracy"] = float(np.nanmax(result.stated_accuracy, initial=0.0))
        ds.dims[0].attach_scale(member)
        ds.dims[1].attach_scale(dof)


def _write_response(f, response, member, dof, family, normalized: bool) -> None:
    freq = f.create_dataset("frequency", data=response.omega)
    freq.attrs["units"] = "rad/s"
    freq.make_scale("frequency")
    f.attrs["input_dof"] = response.input_dof
    f.attrs["response"] = "exact receptance" if response.exact else "measured by simulation to steady state"

    def stacked(group, name, data, units):
        ds = group.create_dataset(name, data=data)
        ds.attrs["units"] = units
        ds.dims[0].attach_scale(member)
        ds.dims[1].attach_scale(freq)
        ds.dims[2].attach_scale(dof)
        return ds

    if response.exact:
        stacked(f, "amplitude", response.amplitude, "m/N")
        stacked(f, "phase", response.phase, "rad")
    if normalized:  # the book's Equation (9-34) axes, 1 DOF: X K / F0 against r = omega / omega_n
        k = family.K[:, 0, 0]
        ratio = f.create_dataset("frequency_ratio", data=response.omega[None, :] / np.sqrt(k / family.M[:, 0, 0])[:, None])
        ratio.dims[0].attach_scale(member)
        ratio.dims[1].attach_scale(freq)
        if response.exact:
            stacked(f, "normalized_amplitude", response.amplitude * k[:, None, None], "1")
    for direction, (amp, lag) in response.measured.items():
        group = f.create_group(f"measured/{direction}")
        stacked(group, "amplitude", amp, "m/N")
        stacked(group, "phase", lag, "rad")
        ds = group.create_dataset("steady", data=response.steady[direction])
        ds.dims[0].attach_scale(member)
        ds.dims[1].attach_scale(freq)
    if response.difference is not None:
        f["measured"].attrs["max_difference_from_exact"] = response.difference
    peaks = f.create_group("peaks")
    peaks.create_dataset("member", data=np.array([p["member"] for p in response.peaks], dtype=int))
    _strings(peaks, "dof", [p["dof"] for p in response.peaks])
    peaks.create_dataset("omega", data=np.array([p["omega"] for p in response.peaks], dtype=float))
    peaks.create_dataset("amplitude", data=np.array([p["amplitude"] for p in response.peaks], dtype=float))
    _strings(peaks, "source", [f"measured, sweep {p['direction']}" if "direction" in p else "exact"
                               for p in response.peaks])
