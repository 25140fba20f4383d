"""The files of `smd optimize`: OUT/<stem>_optimize.h5 (the bounds, the start, the optimum, the objective before and
at it, every distinct optimum found, the path taken, a receptance's peaks) and OUT/<stem>_optimized.toml (the scene
with the optimum written in: `smd simulate` runs it as it is).

Must not import: commands, cli.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from smdcli.io.atomic import atomic_path
from smdcli.io.fit_hdf5 import _moved
from smdcli.io.hdf5 import axis, with_scales, write_provenance


def write_optimize(path: Path, run) -> None:
    """/parameter, /lower, /upper, /initial, /optimum, /gradient, /objective (before, at the optimum), /optima/...,
    /history/objective and /history/parameters (the best start's path), /constraints/... (each one's limit, value at
    the optimum, whether it binds), /peaks/before and /peaks/optimum (a receptance's: frequency rad/s, |H| m/N; a peak in time's: time s,
    |x| m); root
    attributes objective, converged, message, iterations, solves."""
    import h5py

    from smdcli.sweep.spec import parameter_units

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "optimize")
        f.attrs["title"] = f"Optimum of {Path(run.scenario).name}: minimize {run.objective}"
        f.attrs["scenario_path"] = run.scenario
        for key in ("objective", "converged", "message", "iterations", "solves", "wall_time_s"):
            value = getattr(run, key)
            f.attrs[key] = value if not isinstance(value, bool) else int(value)
        parameter = axis(f, "parameter", list(run.parameter))
        units = np.array([parameter_units(p, run.sc) or "1" for p in run.parameter], dtype=h5py.string_dtype())
        for name in ("lower", "upper", "initial", "optimum"):
            ds = with_scales(f.create_dataset(name, data=getattr(run, name)), parameter)
            ds.attrs["units"] = units
        ds = with_scales(f.create_dataset("gradient", data=run.gradient), parameter)
        ds.attrs["description"] = "d objective / d parameter at the optimum (the largest peak's, for a receptance)"
        ds = with_scales(f.create_dataset("on_bound", data=run.on_bound), parameter)
        ds.attrs["description"] = "-1 at the lower bound, +1 at the upper, 0 inside"
        ds = f.create_dataset("objective", data=np.array([run.value_before, run.value]))
        ds.attrs["units"], ds.attrs["description"] = run.units, "the objective at the start and at the optimum"
        optima = f.create_group("optima")
        found = axis(optima, "optimum", np.arange(len(run.optima)))
        with_scales(optima.create_dataset("parameters", data=np.array([o for o, _ in run.optima])), found, parameter)
        with_scales(optima.create_dataset("objective", data=np.array([v for _, v in run.optima])), found)
        history = f.create_group("history")
        step = axis(history, "evaluation", np.arange(len(run.history_objective)))
        with_scales(history.create_dataset("objective", data=run.history_objective), step)
        with_scales(history.create_dataset("parameters", data=run.history_parameters), step, parameter)
        if run.records:
            f.attrs["over"] = run.over
            group = f.create_group("records")
            axis(group, "record", [path for path, _ in run.records])
            group.create_dataset("objective", data=np.array([value for _, value in run.records]))
        if run.constraints:
            bound = f.create_group("constraints")
            axis(bound, "constraint", [text for text, *_ in run.constraints])
            bound.create_dataset("limit", data=np.array([c[1] for c in run.constraints]))
            bound.create_dataset("value", data=np.array([c[2] for c in run.constraints]))
            bound.create_dataset("binds", data=np.array([int(c[3]) for c in run.constraints]))
        if len(run.peaks):
            peaks = f.create_group("peaks")
            for name, rows in (("before", run.peaks_before), ("optimum", run.peaks)):
                ds = peaks.create_dataset(name, data=rows)
                name, unit = run.peak_axis
                ds.attrs["columns"] = np.array([f"{name} {unit}", f"value {run.units}"], dtype=h5py.string_dtype())


def optimized_toml(run, out_dir: Path) -> str:
    """The scenario's TOML with the optimum written in, a comment saying what it minimizes, file paths rewritten
    relative to the folder it is written to."""
    import tomli_w

    from smdcli.sweep.family import set_parameter

    doc = tomllib.loads(run.sc.text)
    for path, value in zip(run.parameter, run.optimum):
        set_parameter(doc, path, float(value))
    _moved(doc, Path(run.scenario).resolve().parent, out_dir.resolve())
    lines = [f"# Optimized by smd optimize (from {run.scenario}): minimize {run.objective}, "
             f"{run.value_before:.6g} -> {run.value:.6g} {run.units}"]
    lines += [f"# {p} = {v:.10g}" + ("  (on its bound)" if b else "") for p, v, b in
              zip(run.parameter, run.optimum, run.on_bound)]
    if not run.converged:
        lines.append(f"# the search did not converge: {run.message}")
    return "\n".join(lines) + "\n" + tomli_w.dumps(doc)
