"""`smd sensitivity`: a linear scene's response and its exact derivatives with respect to parameters given by
the sweep's paths (spring[0].k, mass.m1.m, damper[1].c, force[0].omega, ground_motion.scale, ...).

Must not import: cli.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.io.folders import output_folder


def sensitivity_command(path: str | Path, params: list[str], out: str | Path, plots: bool = True,
                        progress: bool = False):
    """Read the scene, take its sensitivities, write OUT/<stem>_sensitivity.h5 (and .png); a bar on a terminal over a
    nonlinear scene's output times (its integration takes seconds)."""
    from smdcli.analysis.sensitivity import sensitivity
    from smdcli.io.atomic import together
    from smdcli.io.sensitivity_hdf5 import write_sensitivity
    from smdcli.solvers.run import load

    path = Path(path)
    sc = load(path)
    out_dir = output_folder(out, make=False)
    from smdcli.model import time_grid
    from smdcli.progress import bar

    with bar("sensitivities", len(time_grid(sc.time)), enabled=progress, transient=True) as advance:
        s = sensitivity(sc, list(params), timed=True, advance=advance)
    out_dir = output_folder(out)
    with together():
        h5 = out_dir / f"{path.stem}_sensitivity.h5"
        write_sensitivity(h5, sc, s)
        s.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.sensitivity import sensitivity_figure

            png = out_dir / f"{path.stem}_sensitivity.png"
            save_figure(sensitivity_figure(s), png)
            s.outputs.append(png)
    return s


def _number(x: float) -> float | None:
    """A float for JSON: nan (no derivative) as null."""
    return float(x) if np.isfinite(x) else None


def sensitivity_summary(s) -> dict:
    """The metrics and their derivatives as plain data."""
    return {
        "scenario": s.scenario, "status": "ok", "exit_code": 0, "method": s.method,
        "parameters": [{"path": p, "value": float(v), "units": u or "1", "derivative_units": s.units("displacement")[i],
                        "stated_accuracy": float(s.accuracy["d_displacement"][i])}
                       for i, (p, v, u) in enumerate(zip(s.parameter, s.value, s.parameter_units))],
        "peak_displacement": {dof: {"value": float(s.peak_displacement[j]), "time": float(s.peak_time[j]),
                                    "derivative": {p: _number(s.d_peak_displacement[i, j])
                                                   for i, p in enumerate(s.parameter)}}
                              for j, dof in enumerate(s.dof)},
        "wall_time_s": s.wall_time_s, "forward_solve_s": s.forward_time_s,
        "notes": list(s.notes), "outputs": [str(p) for p in s.outputs]}


# how the method's text says the sensitivity equations were integrated, and the terminal's words for it
INTEGRATED = (("compiled Radau IIA 5 where", "compiled Radau IIA where a piece is stiff, DOP853 elsewhere"),
              ("compiled Radau IIA", "compiled Radau IIA (stiff)"), ("compiled DOP853", "compiled DOP853"))


def format_sensitivity(d: dict) -> str:
    """Terminal text: each DOF's peak and its derivatives, per unit and per 100 % of each parameter."""
    from smdcli.text import plural

    integrated = next((short for long, short in INTEGRATED if long in d["method"]), "DOP853 in Python")
    between = " from event to event" if "from event to event" in d["method"] else ""
    how = "exact" if d["method"].startswith("exact") else f"forward sensitivity equations{between}, {integrated}"
    lines = [f"{d['scenario']}: sensitivities of the peak displacement ({plural(len(d['parameters']), 'parameter')}, "
             f"{how})"]
    width = max(len(p["path"]) for p in d["parameters"])
    from smdcli.commands.simulate import SHOWN, listed

    items = list(d["peak_displacement"].items())
    shown, largest = listed(items, lambda peak: peak["value"])
    if largest is not None and largest not in shown:
        shown = [*shown, largest]
    for dof, peak in shown:
        lines.append(f"  {dof}: peak |x| {peak['value']:.6g} m at t = {peak['time']:.6g} s")
        for p in d["parameters"]:
            value = peak["derivative"][p["path"]]
            if value is None:
                lines.append(f"    d/d {p['path']:<{width}}  none (the peak has no derivative)")
                continue
            relative = value * p["value"] / peak["value"] if peak["value"] else float("nan")
            lines.append(f"    d/d {p['path']:<{width}}  {value: .6g} {p['derivative_units']}"
                         f"   ({relative:+.4g} % per % of {p['value']:.4g}{'' if p['units'] == '1' else ' ' + p['units']})")
    if len(shown) < len(items):
        lines.append(f"  ... ({len(items)} DOFs: the first {SHOWN // 2} and the largest peak shown; --json and the "
                     "file list every one)")
    for note in d["notes"]:
        lines.append(f"  note: {note}")
    if d["outputs"]:
        lines.append(f"  wrote {', '.join(d['outputs'])}")
    return "\n".join(lines)
