"""HDF5 results: written to a temporary name in the target folder, renamed when complete."""

from __future__ import annotations

import hashlib
import os
import tempfile
from contextlib import contextmanager, suppress
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from smdcli import __version__, interrupts, provenance
from smdcli.model import Model
from smdcli.result import Result
from smdcli.scenario import Scenario
from smdcli.solvers.base import acceleration_accuracy

SCHEMA_VERSION = 1


_pending: list[tuple[str, Path]] | None = None  # inside together(): renames waiting for the block's end


def _commit(renames: list[tuple[str, Path]]) -> None:
    """Rename temporary files onto their final names, unless a signal came (even one whose exception was swallowed)."""
    with interrupts.held():  # the check and the renames are one step for a signal
        interrupts.raise_if_received()
        for tmp, final in renames:
            os.replace(tmp, final)


def _discard(paths) -> None:
    with interrupts.held():
        for tmp in paths:
            with suppress(OSError):
                os.unlink(tmp)


@contextmanager
def together():
    """Files written with atomic_path inside the block appear together when it ends, or none of them does."""
    global _pending
    outer, _pending = _pending, []
    try:
        yield
        renames = _pending
        if outer is not None:
            outer.extend(renames)
        else:
            _commit(renames)
    except BaseException:
        _discard(tmp for tmp, _ in _pending)
        raise
    finally:
        _pending = outer


@contextmanager
def atomic_path(final: Path):
    """Yield a temporary path beside `final`; rename it onto `final` only if the block succeeds
    (inside together(): when that block ends)."""
    final = Path(final)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".part", dir=final.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file private (0600); the result gets what the user's umask gives any new file.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        if _pending is not None:
            _pending.append((tmp, final))
        else:
            _commit([(tmp, final)])
    except BaseException:
        _discard([tmp])
        raise


def write_header(f, scenario: Scenario, kind: str) -> None:
    """The root attributes every smd file carries, and the provenance to run it again from the file alone."""
    import platform

    import h5py
    import scipy

    f.attrs["smd_version"] = __version__
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["kind"] = kind
    f.attrs["created"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    f.attrs["title"] = scenario.title
    f.attrs["scenario"] = scenario.text
    f.attrs["scenario_path"] = str(scenario.path)
    f.attrs["command_line"] = provenance.command_line()
    f.attrs["python_version"] = platform.python_version()
    f.attrs["numpy_version"] = np.__version__
    f.attrs["scipy_version"] = scipy.__version__
    f.attrs["h5py_version"] = h5py.__version__
    f.attrs["machine"] = f"{platform.system()} {platform.machine()}"
    tables = [force for force in scenario.forces if force.file]
    if tables:  # the files a table force read, copied: the scenario text alone no longer says what they held
        group = f.create_group("provenance/table_files")
        for force in tables:
            ds = group.create_dataset(force.path, data=force.file_text)
            ds.attrs["file"] = force.file
            ds.attrs["sha256"] = hashlib.sha256(force.file_text.encode()).hexdigest()


def _with_scales(ds, *scales):
    """Attach one dimension scale per axis (None leaves an axis bare); returns the data set."""
    for axis, scale in enumerate(scales):
        if scale is not None:
            ds.dims[axis].attach_scale(scale)
    return ds


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
            if name in ("displacement", "velocity"):  # the applied force is evaluated, not solved for
                ds.attrs["stated_accuracy"] = result.stats.stated_accuracy
            elif name == "acceleration":
                ds.attrs["stated_accuracy"] = acceleration_accuracy(model.M, model.C, model.K,
                                                                    result.stats.stated_accuracy, result.displacement,
                                                                    result.velocity, result.acceleration, result.force)

        solver = f.create_group("solver")
        for key, value in result.stats.as_attrs().items():
            solver.attrs[key] = value
        if result.t_failed is not None:
            solver.attrs["t_failed"] = result.t_failed

        group = f.create_group("model")
        write_matrices(group, model, dof)
        modes = group.create_group("modes")
        m = model.modes
        modes.attrs["natural_frequencies_rad_s"] = m.natural_frequencies
        modes.attrs["damping_ratios"] = m.damping_ratios
        modes.attrs["regimes"] = np.array(m.regimes, dtype=object).astype(str).tolist()
        modes.attrs["stiffness_ratio"] = model.stiffness_ratio
        mode = modes.create_dataset("mode", data=np.arange(1, model.n + 1))
        mode.make_scale("mode")
        for name, data, units in (("natural_frequencies_rad_s", m.natural_frequencies, "rad/s"),
                                  ("damping_ratios", m.damping_ratios, "1")):
            _with_scales(modes.create_dataset(name, data=data), mode).attrs["units"] = units
        shapes = _with_scales(modes.create_dataset("shapes", data=m.shapes), dof, mode)
        shapes.attrs["units"] = "1"
        shapes.attrs["normalization"] = "mass-normalized (shapes^T M shapes = I), largest entry of each column positive"
        eigen = modes.create_dataset("eigenvalues", data=np.stack([m.eigenvalues.real, m.eigenvalues.imag], axis=1))
        eigen.attrs["units"] = "1/s"
        eigen.attrs["columns"] = ["real", "imag"]
        if model.nonlinear_paths:
            group.attrs["nonlinear_elements"] = list(model.nonlinear_paths)


def write_matrices(group, model_or_family, dof, member=None) -> None:
    """M, C, K with units, their axes named by the DOF scale (and the member scale for a family)."""
    for name, units in (("M", "kg"), ("C", "N s/m"), ("K", "N/m")):
        ds = group.create_dataset(name, data=getattr(model_or_family, name))
        ds.attrs["units"] = units
        axes = (dof, dof) if member is None else (member, dof, dof)
        _with_scales(ds, *axes)


def _strings(f, name: str, values):
    """A data set of UTF-8 strings."""
    import h5py

    return f.create_dataset(name, data=np.array(list(values), dtype=object), dtype=h5py.string_dtype("utf-8"))


def write_sweep(path: Path, family, result=None, metrics=None, response=None, run: dict | None = None) -> None:
    """Write a sweep: members on a leading axis (a dimension scale), the swept values, stacked results or a frequency response."""
    import h5py

    from smdcli.sweep import parameter_units

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
                stated = max(acceleration_accuracy(family.M[s], family.C[s], family.K[s], result.stated_accuracy[s],
                                                   result.displacement[s], result.velocity[s],
                                                   result.acceleration[s], result.force[s])
                             for s in range(len(family)))
            ds.attrs["stated_accuracy"] = stated
        ds.dims[0].attach_scale(member)
        if result.time.ndim == 1:
            ds.dims[1].attach_scale(time)
        ds.dims[2].attach_scale(dof)
    f.create_dataset("success", data=result.success).dims[0].attach_scale(member)
    _strings(f, "message", result.messages).dims[0].attach_scale(member)
    _strings(f, "method", result.methods).dims[0].attach_scale(member)
    from smdcli.sweep import METRIC_UNITS, SETTLING_BAND

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
