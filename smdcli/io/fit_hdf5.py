"""The files of `smd fit`: OUT/<stem>_fit.h5 (the estimates, their uncertainty, each channel measured, fitted and
its residual, the history) and OUT/<stem>_fitted.toml per scenario (the scene with the estimates written in: `smd
simulate` runs it as it is).

Must not import: commands, cli.
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

import numpy as np

from smdcli.io.atomic import atomic_path
from smdcli.io.hdf5 import axis, with_scales, write_provenance
from smdcli.analysis.fit_data import SI_UNITS, quantity_of


def write_fit(path: Path, run) -> None:
    """The fit file: /parameter, /initial, /estimate, /standard_error, /covariance, /correlation, /confidence_95,
    /lower, /upper, /time and /measured, /fitted, /residual (a data set per channel; a group per scenario stem
    when several), /history/cost and /history/estimate; root attributes cost, rms_residual, unexplained, warning,
    retried, iterations, solves, converged, message, jacobian."""
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_provenance(f, "fit")
        f.attrs["title"] = f"Fit of {', '.join(Path(t.scenario.path).name for t in run.tests)}"
        f.attrs["scenario_paths"] = np.array([str(t.scenario.path) for t in run.tests], dtype=h5py.string_dtype())
        f.attrs["data_files"] = np.array([t.measured.file for t in run.tests], dtype=h5py.string_dtype())
        for key in ("cost", "rms_residual", "unexplained", "warning", "retried", "iterations", "solves", "converged",
                    "message", "jacobian", "condition", "identifiable", "null_direction", "wall_time_s"):
            value = getattr(run, key)
            f.attrs[key] = value if not isinstance(value, bool) else int(value)
        parameter = axis(f, "parameter", list(run.parameter))
        bound = axis(f, "bound", ["lower", "upper"])
        units = np.array(run.units, dtype=h5py.string_dtype())
        for name in ("initial", "estimate", "standard_error", "lower", "upper"):
            ds = with_scales(f.create_dataset(name, data=getattr(run, name)), parameter)
            ds.attrs["units"] = units
        for name in ("covariance", "correlation"):
            with_scales(f.create_dataset(name, data=getattr(run, name)), parameter, parameter)
        ds = with_scales(f.create_dataset("confidence_95", data=run.confidence_95), parameter, bound)
        ds.attrs["units"] = units
        ds.attrs["description"] = "estimate -+ t(0.975, m - P) standard error (nan: not identifiable)"
        history = f.create_group("history")
        iteration = axis(history, "iteration", np.arange(len(run.history_cost)))
        with_scales(history.create_dataset("cost", data=run.history_cost), iteration)
        with_scales(history.create_dataset("estimate", data=run.history_estimate), iteration, parameter)
        several = len(run.tests) > 1
        for test, fitted in zip(run.tests, run.fitted):
            base = f.require_group(Path(test.scenario.path).stem) if several else f
            time = base.create_dataset("time", data=test.measured.time)
            time.attrs["units"] = "s"
            time.make_scale("time")
            for group in ("measured", "fitted", "residual"):
                g = base.require_group(group)
                for channel in test.channels:
                    data = {"measured": test.measured.channels[channel], "fitted": fitted[channel],
                            "residual": fitted[channel] - test.measured.channels[channel]}[group]
                    ds = with_scales(g.create_dataset(channel, data=data), time)
                    ds.attrs["units"] = SI_UNITS[quantity_of(channel)]
            base["measured"].attrs["weights"] = test.weights


def fitted_toml(run, test, out_dir: Path) -> str:
    """The scenario's TOML with the estimates written in, a comment per parameter with its standard error, and
    every relative file path it names rewritten relative to the folder the file is written to."""
    import tomli_w

    from smdcli.sweep.family import set_parameter

    doc = tomllib.loads(test.scenario.text)
    for path, value in zip(run.parameter, run.estimate):
        set_parameter(doc, path, float(value))
    here = Path(test.scenario.path).resolve().parent
    _moved(doc, here, out_dir.resolve())
    lines = [f"# Fitted by smd fit to {test.measured.file} (from {test.scenario.path}):"]
    for path, value, error, units in zip(run.parameter, run.estimate, run.standard_error, run.units):
        lines.append(f"# {path} = {value:.10g} {units if units != '1' else ''}".rstrip()
                     + (f"  (standard error {error:.3g})" if np.isfinite(error) else "  (not identifiable)"))
    if not run.converged:
        lines.append(f"# the fit did not converge: {run.message}")
    return "\n".join(lines) + "\n" + tomli_w.dumps(doc)


def _moved(doc: dict, here: Path, there: Path) -> None:
    """Relative file names (a table force's, a record's, [system]'s matrices, an [[expect]] golden's, [fit].data) made
    relative to `there`."""
    def fix(table: dict, key: str) -> None:
        value = table.get(key)
        if isinstance(value, str) and value and not os.path.isabs(value):
            table[key] = os.path.relpath(here / value, there)
    for force in doc.get("force", []):
        fix(force, "file")
    if isinstance(doc.get("ground_motion"), dict):
        fix(doc["ground_motion"], "file")
    if isinstance(doc.get("system"), dict):
        for key in ("M", "C", "K"):
            fix(doc["system"], key)
    for check in doc.get("expect", []):
        fix(check, "file")
    if isinstance(doc.get("fit"), dict):
        fix(doc["fit"], "data")
