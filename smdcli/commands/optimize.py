"""`smd optimize`: the parameters within bounds that minimize a response measure (a receptance's peak, an RMS under
white noise, a run's peak displacement), with exact gradients, from several starts.

Must not import: cli.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.io.folders import output_folder


def optimize_command(path: str | Path, params: list[str], objective: str | None, out: str | Path,
                     starts: int | None = None, input_name: str | None = None, plots: bool = True,
                     progress: bool = False, subject_to: tuple[str, ...] = (), records: tuple[str, ...] = (),
                     over: str = "max", input_psd: str | None = None, psd_units: str | None = None):
    """Read the scene and the bounds (the flags, else its [optimize] table), optimize, write OUT/<stem>_optimize.h5,
    OUT/<stem>_optimized.toml and OUT/<stem>_optimize.png (nothing where the input is refused); a bar over the
    starts on a terminal."""
    from smdcli.analysis.objectives import read_bounds
    from smdcli.analysis.optimize import optimize
    from smdcli.errors import UsageError
    from smdcli.io.atomic import atomic_path, together
    from smdcli.io.optimize_hdf5 import optimized_toml, write_optimize
    from smdcli.progress import bar
    from smdcli.solvers.run import load
    from smdcli.sweep.spec import table_bounds

    path = Path(path)
    sc = load(path)
    table = dict(sc.optimize)
    bounds = [read_bounds(text) for text in params] if params else \
        [(name, *table_bounds(sc, f"optimize.parameters.{name}", name, pair))
         for name, pair in table.get("parameters", ())]
    objective = objective or table.get("minimize")
    if not bounds:
        raise UsageError(f"{path}: nothing to optimize: give --param PATH=LO:HI or [optimize] parameters = {{...}}")
    if not objective:
        raise UsageError(f"{path}: no objective: give --minimize OBJECTIVE or [optimize] minimize = \"...\"")
    subject_to = tuple(subject_to) or tuple(table.get("subject_to", ()))
    if input_psd is None and "input_psd" in table and not table["input_psd"].startswith("white:"):
        input_psd = str(path.parent / table["input_psd"])  # the table's profile is beside the scenario
    psd = _input_psd(sc, input_psd or table.get("input_psd"), psd_units or table.get("psd_units"),
                     input_name or table.get("input"))
    starts = starts if starts is not None else table.get("starts", 8)
    input_name = input_name or table.get("input")
    output_folder(out, make=False)
    with bar("starts", starts, enabled=progress, transient=True) as advance:
        run = optimize(sc, bounds, objective, starts, input_name, advance, tuple(subject_to), tuple(records), over,
                       psd)
    out_dir = output_folder(out)
    with together():
        h5 = out_dir / f"{path.stem}_optimize.h5"
        write_optimize(h5, run)
        toml = out_dir / f"{path.stem}_optimized.toml"
        with atomic_path(toml) as tmp:
            tmp.write_text(optimized_toml(run, out_dir))
        run.outputs += [h5, toml]
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.optimize import optimize_figure

            png = out_dir / f"{path.stem}_optimize.png"
            surface = _surface(run) if len(run.parameter) == 2 else None
            save_figure(optimize_figure(run, *_responses(run), surface=surface), png)
            run.outputs.append(png)
    return run


def _input_psd(sc, spec: str | None, units: str | None, input_name: str | None):
    """The rms measures' input PSD in SI from --input-psd (a two-column profile of Hz and level, or white:LEVEL, as
    `smd psd --input` takes it): levels in g^2/Hz (or --psd-units m/s^2) on a shaking support, N^2/Hz on a force."""
    from smdcli.analysis.optimize import shaken
    from smdcli.commands.psd import read_profile
    from smdcli.errors import UsageError
    from smdcli.model import build
    from smdcli.scenario.spec import STANDARD_GRAVITY

    if spec is None:
        if units is not None:
            raise UsageError(f"--psd-units {units}: given without --input-psd")
        return None
    support = shaken(build(sc), input_name)
    if units not in (None, "g", "m/s^2") or units is not None and not support:
        raise UsageError(f"--psd-units {units}: expected g or m/s^2 for a support acceleration PSD" +
                         ("" if support else " (a force's PSD is in N^2/Hz: no --psd-units)"))
    factor = STANDARD_GRAVITY**2 if support and (units or "g") == "g" else 1.0
    profile, white = read_profile(spec, factor, "--input-psd")
    return white if profile is None else profile


def _surface(run, budget_s: float = 3.0):
    """The objective alone on a grid over two parameters' bounds, as many points a side (7 to 25) as about budget_s
    of solving allows: (the first's values, the second's, the objective (second, first)); nan where the scene is
    not valid or its run fails."""
    import time

    import smdcli
    from smdcli.errors import ScenarioError, SolverFailed

    def value(point):
        try:
            return run.problem.value(np.asarray(point, dtype=float), smdcli.simulate)
        except (ScenarioError, SolverFailed):
            return float("nan")
    begin = time.perf_counter()
    value(run.optimum)
    side = int(np.clip(np.sqrt(budget_s / max(time.perf_counter() - begin, 1e-4)), 7, 25))
    first, second = (np.linspace(lo, hi, side) for lo, hi in zip(run.lower, run.upper))
    return first, second, np.array([[value((a, b)) for a in first] for b in second])


def _responses(run):
    """The objective's response at the start and at the optimum, as the figure draws them."""
    if run.in_frequency:
        from smdcli.plots.optimize import receptance_curve

        return receptance_curve(run, np.clip(run.initial, run.lower, run.upper)), receptance_curve(run, run.optimum)
    import smdcli
    from smdcli.analysis.dissipation import dissipated_history
    from smdcli.sweep.family import scenario_with

    measure = run.problem.objective
    out = []
    for values in (np.clip(run.initial, run.lower, run.upper), run.optimum):
        result = smdcli.simulate(scenario_with(run.sc, dict(zip(run.parameter, map(float, values)))))
        if measure.kind == "dissipated":  # the element's energy as it accumulates
            series = dissipated_history(result, measure.element)
        elif measure.kind == "peak_acceleration":  # absolute, as the objective: relative plus the ground's
            series = result.absolute("acceleration")[:, measure.dof]
        elif measure.kind == "peak_drift" and measure.other >= 0:
            series = result.displacement[:, measure.dof] - result.displacement[:, measure.other]
        else:
            series = result.displacement[:, measure.dof]
        out.append((result.time, series))
    return out


def optimize_summary(run) -> dict:
    """The optimum as plain data."""
    from smdcli.sweep.spec import parameter_units

    return {
        "scenario": run.scenario, "status": "ok" if run.converged else "not converged",
        "exit_code": 0 if run.converged else 1, "objective": run.objective, "units": run.units,
        "before": run.value_before, "optimum_value": run.value,
        "parameters": [{"path": p, "units": parameter_units(p, run.sc) or "1", "lower": float(lo), "upper": float(hi),
                        "initial": float(a), "optimum": float(b), "on_bound": ["lower", None, "upper"][int(e) + 1]}
                       for p, lo, hi, a, b, e in zip(run.parameter, run.lower, run.upper, run.initial, run.optimum,
                                                     run.on_bound)],
        "peaks": [{"_".join(run.peak_axis).replace("/", "_"): float(w), "value": float(h)} for w, h in run.peaks],
        "constraints": [{"constraint": text, "limit": limit, "value": value, "binds": bool(binds)}
                        for text, limit, value, binds in run.constraints],
        "records": [{"file": path, "value": value} for path, value in run.records], "over": run.over,
        "optima": [{"parameters": [float(v) for v in o], "value": float(f)} for o, f in run.optima],
        "converged": run.converged, "message": run.message, "iterations": run.iterations, "solves": run.solves,
        "wall_time_s": run.wall_time_s, "outputs": [str(p) for p in run.outputs]}


def format_optimize(d: dict) -> str:
    """Terminal text: the objective before and at the optimum, each parameter, the active peaks, the optima."""
    unit = "" if d["units"] == "1" else f" {d['units']}"
    lines = [f"{d['scenario']}: minimize {d['objective']}: {d['before']:.6g} -> {d['optimum_value']:.6g}{unit}"
             + ("" if d["converged"] else f" (NOT CONVERGED: {d['message']})")]
    width = max(len(p["path"]) for p in d["parameters"])
    for p in d["parameters"]:
        where = f"  on its {p['on_bound']} bound" if p["on_bound"] else ""
        unit = "" if p["units"] == "1" else f" {p['units']}"
        lines.append(f"  {p['path']:<{width}}  {p['initial']:.6g} -> {p['optimum']:.10g}{unit}"
                     f"   (bounds {p['lower']:.4g} .. {p['upper']:.4g}){where}")
    if d["peaks"]:
        top = max(peak["value"] for peak in d["peaks"])
        active = [peak for peak in d["peaks"] if peak["value"] >= top * (1 - 1e-6)]
        lines.append("  active peaks: " + ", ".join(
            f"{peak['value']:.6g} at {peak['frequency_rad_s']:.6g} rad/s" if "frequency_rad_s" in peak
            else f"{peak['value']:.6g} at t = {peak['time_s']:.6g} s" for peak in active))
    if d["records"]:
        lines.append(f"  over {len(d['records'])} records ({d['over']}): " +
                     ", ".join(f"{Path(r['file']).name} {r['value']:.6g}" for r in d["records"]))
    for c in d["constraints"]:
        lines.append(f"  subject to {c['constraint']}: {c['value']:.6g}" + ("  (binds)" if c["binds"] else ""))
    if len(d["optima"]) > 1:
        lines.append(f"  {len(d['optima'])} distinct optima found: " +
                     "; ".join(f"{o['value']:.6g} at ({', '.join(f'{v:.4g}' for v in o['parameters'])})"
                               for o in d["optima"]))
    lines.append(f"  {d['solves']} solves, {d['wall_time_s']:.3g} s")
    if d["outputs"]:
        lines.append(f"  wrote {', '.join(d['outputs'])}")
    return "\n".join(lines)
