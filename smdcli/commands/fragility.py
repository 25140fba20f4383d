"""`smd fragility`: a lognormal fragility curve fitted by maximum likelihood to an IDA result's collapse intensities
(`RESULT_ida.h5`, its `/collapse_im`) or to multiple-stripe counts (`COUNTS.csv`, columns im,runs,collapses), written
as OUT/<input stem>_fragility.h5 and .png.

Must not import: cli.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.errors import ScenarioError, UsageError

COLUMNS = ("im", "runs", "collapses")


@dataclass
class FragilityRun:
    """A fitted fragility, where its data came from, and the files written."""

    source: str
    fragility: object  # analysis.fragility.Fragility
    im_units: str
    outputs: list[Path] = field(default_factory=list)


def read_counts(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(im, runs, collapses) of a counts file: a header naming im, runs and collapses (any order, any separator),
    one stripe a line; ScenarioError naming the line that is wrong."""
    from smdcli.scenario.records import ColumnsError, _cells, read_text

    try:
        text = read_text(path)
    except ColumnsError as exc:
        raise ScenarioError(str(path), None, str(exc)) from None
    lines = [(number, line.strip()) for number, line in enumerate(text.splitlines(), start=1)
             if line.strip() and not line.strip().startswith("#")]
    if not lines:
        raise ScenarioError(str(path), None, "expected a header im,runs,collapses and a line per stripe, found no lines")
    header = [cell.lower() for cell in _cells(lines[0][1])]
    if sorted(header) != sorted(COLUMNS):
        raise ScenarioError(str(path), None, f"line {lines[0][0]}: expected the header im,runs,collapses, found "
                                             f"{lines[0][1][:40]!r}")
    order = [header.index(name) for name in COLUMNS]
    rows = []
    for number, line in lines[1:]:
        cells = _cells(line)
        try:
            values = [float(cells[i]) for i in order] if len(cells) == 3 else None
        except ValueError:
            values = None
        if values is None:
            raise ScenarioError(str(path), None, f"line {number}: expected three numbers (im, runs, collapses), found "
                                                 f"{line[:40]!r}")
        im, runs, collapses = values
        if not (np.isfinite(im) and im > 0):
            raise ScenarioError(str(path), None, f"line {number}: expected a positive intensity, found {im:g}")
        if not (runs >= 1 and runs == int(runs) and collapses == int(collapses) and 0 <= collapses <= runs):
            raise ScenarioError(str(path), None, f"line {number}: expected whole runs >= 1 and 0 <= collapses <= runs, "
                                                 f"found runs {runs:g}, collapses {collapses:g}")
        rows.append(values)
    if len(rows) < 2:
        raise ScenarioError(str(path), None, f"expected at least two stripes, found {len(rows)}")
    im, runs, collapses = (np.array(column) for column in zip(*rows))
    return im, runs, collapses


def read_collapse_intensities(path: Path) -> tuple[np.ndarray, str]:
    """An IDA result's collapse intensities (/collapse_im, finite ones: a record that never collapsed has none)
    and their units."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if "collapse_im" not in f:
                raise ScenarioError(str(path), None, "expected an smd ida result with /collapse_im")
            im = np.asarray(f["collapse_im"][()], dtype=float).ravel()
            units = str(f.attrs.get("im_units", f["collapse_im"].attrs.get("units", "")))
    except OSError:
        raise ScenarioError(str(path), None, "expected an HDF5 file (an smd ida result), found something else") from None
    im = im[np.isfinite(im)]
    if len(im) < 2 or (im <= 0).any():
        raise ScenarioError(str(path), None, f"expected at least two positive collapse intensities, found {len(im)}")
    return im, units


def fragility_command(path: str | Path, out: str | Path, plots: bool = True) -> FragilityRun:
    """Fit, write OUT/<stem>_fragility.h5 (and .png), return the run."""
    from smdcli.analysis.fragility import from_collapse_intensities, from_stripes
    from smdcli.io.folders import output_folder

    path = Path(path)
    if not path.is_file():
        raise UsageError(f"{path}: no such file")
    try:
        if path.suffix.lower() in (".h5", ".hdf5"):
            im, units = read_collapse_intensities(path)
            fitted = from_collapse_intensities(im)
        else:
            fitted, units = from_stripes(*read_counts(path)), ""
    except ValueError as exc:
        raise ScenarioError(str(path), None, str(exc)) from None
    run = FragilityRun(str(path), fitted, units)
    out_dir = output_folder(out)
    from smdcli.io.atomic import together
    from smdcli.io.fragility_hdf5 import write_fragility

    with together():
        h5 = out_dir / f"{path.stem}_fragility.h5"
        write_fragility(h5, run)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.fragility import fragility_figure

            png = out_dir / f"{path.stem}_fragility.png"
            save_figure(fragility_figure(fitted, units, path.name), png)
            run.outputs.append(png)
    return run


def fragility_summary(run: FragilityRun) -> dict:
    """The fit as plain data."""
    f = run.fragility
    return {"source": run.source, "status": "ok", "exit_code": 0, "method": f.method, "im_units": run.im_units,
            "theta": f.theta, "beta": f.beta, "theta_95": list(f.theta_95), "beta_95": list(f.beta_95),
            "log_likelihood": f.log_likelihood, "data_points": len(f.im), "outputs": [str(o) for o in run.outputs]}


def format_fragility(d: dict) -> str:
    """Terminal text for a fit."""
    units = f" {d['im_units']}" if d["im_units"] else ""
    lines = [f"{d['source']}: lognormal fragility by maximum likelihood ({d['method']}, {d['data_points']} "
             f"{'records' if d['method'] == 'collapse intensities' else 'stripes'})",
             f"  median theta {d['theta']:.6g}{units}  (95 % profile likelihood {d['theta_95'][0]:.4g} .. "
             f"{d['theta_95'][1]:.4g})",
             f"  dispersion beta {d['beta']:.6g}  (95 % {d['beta_95'][0]:.4g} .. {d['beta_95'][1]:.4g})"]
    if d["outputs"]:
        lines.append(f"  wrote {', '.join(d['outputs'])}")
    return "\n".join(lines)
