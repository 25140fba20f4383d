"""`smd fit`: one or more scenarios' parameters fitted to measured response (see smdcli.analysis.fit).

Must not import: cli.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from smdcli.errors import UsageError
from smdcli.io.folders import output_folder


def read_bound(text: str) -> tuple[str, tuple[float, float]]:
    """PATH=LO:HI as (path, (lo, hi))."""
    path, _, span = text.partition("=")
    lo, _, hi = span.partition(":")
    try:
        pair = (float(lo), float(hi))
    except ValueError:
        pair = (math.nan, math.nan)
    if not path or not pair[0] < pair[1]:
        raise UsageError(f"--bound: expected PATH=LOWER:UPPER with LOWER < UPPER, found {text!r}")
    return path.strip(), pair


def fit_command(paths: list[Path], data: list[Path], params: list[str], bounds: list[str], out: str | Path,
                max_iterations: int = 100, plots: bool = True, progress: bool = False):
    """Read every scenario and data file first (input errors before any work), fit, write OUT/<stem>_fit.h5,
    OUT/<stem>_fitted.toml per scenario and OUT/<stem>_fit.png."""
    from smdcli.analysis.fit import fit, make_test
    from smdcli.analysis.fit_data import read_measured
    from smdcli.analysis.model_derivative import check_once
    from smdcli.solvers.run import load
    from smdcli.sweep.spec import table_bounds

    scenarios = [load(p) for p in paths]
    tables = [dict(sc.fit) for sc in scenarios]
    if data and len(data) != len(scenarios):
        raise UsageError(f"--data: give one data file per scenario ({len(scenarios)}), found {len(data)}")
    files = []
    for sc, table, given in zip(scenarios, tables, data or [None] * len(scenarios)):
        if given is None and "data" not in table:
            raise UsageError(f"{sc.path}: no data to fit: give --data FILE or [fit] data = \"FILE\"")
        files.append(Path(given) if given is not None else Path(sc.path).parent / table["data"])
    params = list(params) or list(tables[0].get("parameters", ()))
    if not params:
        raise UsageError(f"{scenarios[0].path}: no parameter to fit: give --param PATH or [fit] parameters = [...]")
    check_once(params)
    chosen = {name: table_bounds(scenarios[0], f"fit.bounds.{name}", name, pair)
              for name, pair in tables[0].get("bounds", ())}
    chosen.update(read_bound(b) for b in bounds)
    if max_iterations < 1:
        raise UsageError(f"--max-iterations: expected a positive number, found {max_iterations}")
    measured = [read_measured(f) for f in files]
    tests = [make_test(sc, m) for sc, m in zip(scenarios, measured)]
    out_dir = output_folder(out, make=False)
    from smdcli.progress import bar

    with bar("fitting (solves)", max_iterations, enabled=progress, transient=True) as advance:
        run = fit(tests, params, chosen, max_iterations, advance)
    out_dir = output_folder(out)
    from smdcli.io.atomic import atomic_path, together
    from smdcli.io.fit_hdf5 import fitted_toml, write_fit

    stem = Path(scenarios[0].path).stem
    with together():
        h5 = out_dir / f"{stem}_fit.h5"
        write_fit(h5, run)
        run.outputs.append(h5)
        for test in tests:
            toml = out_dir / f"{Path(test.scenario.path).stem}_fitted.toml"
            with atomic_path(toml) as tmp:
                tmp.write_text(fitted_toml(run, test, out_dir))
            run.outputs.append(toml)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.fit import fit_figure

            png = out_dir / f"{stem}_fit.png"
            save_figure(fit_figure(run), png)
            run.outputs.append(png)
    return run


def _number(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def fit_summary(run) -> dict:
    """The estimates, their uncertainty and the fit's course as plain data (nan as null)."""
    P = len(run.parameter)
    pairs = sorted(((abs(run.correlation[i, j]), i, j) for i in range(P) for j in range(i + 1, P)
                    if np.isfinite(run.correlation[i, j])), reverse=True)
    return {
        "scenarios": [str(t.scenario.path) for t in run.tests], "data": [t.measured.file for t in run.tests],
        "status": "ok" if run.converged else "not converged", "exit_code": 0 if run.converged else 1,
        "converged": run.converged, "message": run.message, "iterations": run.iterations, "solves": run.solves,
        "cost": run.cost, "rms_residual": run.rms_residual, "unexplained": _number(run.unexplained),
        "warning": run.warning or None, "retried": run.retried or None, "jacobian": run.jacobian,
        "identifiable": run.identifiable, "condition": run.condition if math.isfinite(run.condition) else None,
        "null_direction": run.null_direction or None,
        "parameters": [{"path": p, "units": u, "initial": float(a), "estimate": float(e),
                        "standard_error": _number(s), "confidence_95": [_number(c[0]), _number(c[1])]}
                       for p, u, a, e, s, c in zip(run.parameter, run.units, run.initial, run.estimate,
                                                   run.standard_error, run.confidence_95)],
        "largest_correlations": [{"between": [run.parameter[i], run.parameter[j]],
                                  "correlation": float(run.correlation[i, j])} for _, i, j in pairs[:3]],
        "wall_time_s": run.wall_time_s, "outputs": [str(p) for p in run.outputs]}


def format_fit(d: dict) -> str:
    """The terminal table: parameter, initial, estimate, standard error, 95 % interval; the largest correlations."""
    head = "converged" if d["converged"] else "NOT CONVERGED"
    lines = [f"{', '.join(d['scenarios'])}: fit to {', '.join(d['data'])}: {head} in {d['iterations']} iterations "
             f"({d['solves']} solves), RMS weighted residual {d['rms_residual']:.4g}"]
    width = max(len(p["path"]) for p in d["parameters"])
    lines.append(f"  {'parameter':<{width}}  {'initial':>12}  {'estimate':>14}  {'std. error':>10}  95 % interval")
    for p in d["parameters"]:
        error = f"{p['standard_error']:.3g}" if p["standard_error"] is not None else "-"
        low, high = p["confidence_95"]
        interval = f"[{low:.8g}, {high:.8g}]" if low is not None else "not identifiable"
        lines.append(f"  {p['path']:<{width}}  {p['initial']:>12.6g}  {p['estimate']:>14.9g}  {error:>10}  "
                     f"{interval} {p['units'] if p['units'] != '1' else ''}".rstrip())
    if d["largest_correlations"]:
        lines.append("  correlations: " + ", ".join(f"{a} ~ {b} {c['correlation']:+.3f}" for c in
                                                    d["largest_correlations"] for a, b in [c["between"]]))
    if not d["identifiable"]:
        lines.append(f"  not identifiable: the data do not determine {d['null_direction']} (condition "
                     f"{d['condition'] if d['condition'] is not None else 'inf'})")
    if not d["converged"]:
        lines.append(f"  {d['message']}")
    elif d["retried"]:
        lines.append(f"  {d['retried']}")
    if d["warning"]:
        lines.append(f"  warning: {d['warning']}")
    if d["outputs"]:
        lines.append(f"  wrote {', '.join(d['outputs'])}")
    return "\n".join(lines)
