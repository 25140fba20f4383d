"""HDF5 results: written to a temporary name in the target folder, renamed when complete."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager, suppress
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from smdcli import __version__
from smdcli.model import Model
from smdcli.result import Result
from smdcli.scenario import Scenario

SCHEMA_VERSION = 1


@contextmanager
def atomic_path(final: Path):
    """Yield a temporary path beside `final`; rename it onto `final` only if the block succeeds."""
    final = Path(final)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".part", dir=final.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file private (0600); the result gets what the user's umask gives any new file.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, final)
    except BaseException:
        with suppress(OSError):
            os.unlink(tmp)
        raise


def write_header(f, scenario: Scenario, kind: str) -> None:
    """The root attributes every smd file carries."""
    f.attrs["smd_version"] = __version__
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["kind"] = kind
    f.attrs["created"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    f.attrs["title"] = scenario.title
    f.attrs["scenario"] = scenario.text
    f.attrs["scenario_path"] = str(scenario.path)


def write_simulation(path: Path, scenario: Scenario, model: Model, result: Result) -> None:
    """Write one simulate run in the layout of DESIGN.md."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_header(f, scenario, "simulate")

        time = f.create_dataset("time", data=result.time)
        time.attrs["units"] = "s"
        time.make_scale("time")
        dof = _strings(f, "dof", result.dofs)
        dof.make_scale("dof")
        for name, data, units in (
            ("displacement", result.displacement, "m"),
            ("velocity", result.velocity, "m/s"),
            ("acceleration", result.acceleration, "m/s^2"),
            ("force", result.force, "N"),
        ):
            ds = f.create_dataset(name, data=data)
            ds.attrs["units"] = units
            ds.dims[0].attach_scale(time)
            ds.dims[1].attach_scale(dof)

        solver = f.create_group("solver")
        for key, value in result.stats.as_attrs().items():
            solver.attrs[key] = value
        if result.t_failed is not None:
            solver.attrs["t_failed"] = result.t_failed

        group = f.create_group("model")
        for name in ("M", "C", "K"):
            group.create_dataset(name, data=getattr(model, name))
        modes = group.create_group("modes")
        m = model.modes
        modes.attrs["natural_frequencies_rad_s"] = m.natural_frequencies
        modes.attrs["damping_ratios"] = m.damping_ratios
        modes.attrs["regimes"] = np.array(m.regimes, dtype=object).astype(str).tolist()
        modes.attrs["stiffness_ratio"] = model.stiffness_ratio
        modes.create_dataset("natural_frequencies_rad_s", data=m.natural_frequencies)
        modes.create_dataset("damping_ratios", data=m.damping_ratios)
        modes.create_dataset("shapes", data=m.shapes)
        modes.create_dataset("eigenvalues", data=np.stack([m.eigenvalues.real, m.eigenvalues.imag], axis=1))
        if model.nonlinear_paths:
            group.attrs["nonlinear_elements"] = list(model.nonlinear_paths)


def _strings(f, name: str, values):
    """A data set of UTF-8 strings."""
    import h5py

    return f.create_dataset(name, data=np.array(list(values), dtype=object), dtype=h5py.string_dtype("utf-8"))


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
        for i, name in enumerate(spec.parameters):
            ds = params.create_dataset(name, data=family.values[:, i])
            ds.dims[0].attach_scale(member)
        dof = _strings(f, "dof", family.base.dofs)
        dof.make_scale("dof")
        initial = f.create_group("initial_conditions")
        for name in ("x0", "v0"):
            ds = initial.create_dataset(name, data=getattr(family, name))
            ds.dims[0].attach_scale(member)
            ds.dims[1].attach_scale(dof)
        model = f.create_group("model")
        for name in ("M", "C", "K"):
            model.create_dataset(name, data=getattr(family, name))
        if run:
            group = f.create_group("run")
            for key, value in run.items():
                group.attrs[key] = value
        if result is not None:
            _write_time_family(f, result, metrics, member, dof)
        if response is not None:
            _write_response(f, response, member, dof, family, spec.normalized)


def _write_time_family(f, result, metrics, member, dof) -> None:
    time = f.create_dataset("time", data=result.time)
    time.attrs["units"] = "s"
    if result.time.ndim == 1:
        time.make_scale("time")
    for name, units in (("displacement", "m"), ("velocity", "m/s"), ("acceleration", "m/s^2"), ("force", "N")):
        ds = f.create_dataset(name, data=np.ascontiguousarray(getattr(result, name)))
        ds.attrs["units"] = units
        ds.dims[0].attach_scale(member)
        if result.time.ndim == 1:
            ds.dims[1].attach_scale(time)
        ds.dims[2].attach_scale(dof)
    f.create_dataset("success", data=result.success).dims[0].attach_scale(member)
    _strings(f, "message", result.messages).dims[0].attach_scale(member)
    _strings(f, "method", result.methods).dims[0].attach_scale(member)
    from smdcli.sweep import SETTLING_BAND

    group = f.create_group("metrics")
    group.attrs["settling_band"] = SETTLING_BAND
    for name, values in metrics.items():
        ds = group.create_dataset(name, data=values)
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
