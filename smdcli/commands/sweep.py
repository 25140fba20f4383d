"""`smd sweep`: load, build the family, solve it, write `<stem>_sweep.h5` and the plots; summaries.

Must not import: cli."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from smdcli import scenario as scenario_mod
from smdcli.errors import UsageError
from smdcli.progress import bar
from smdcli.sweep.family import Family, build_family
from smdcli.sweep.frequency import FrequencyResponse, _driving_force, frequency_response, input_index
from smdcli.sweep.members import FamilyResult, metrics, solve_family
from smdcli.sweep.shooting import MAX_PERIODS
from smdcli.sweep.spec import METRIC_UNITS, read_spec
from smdcli.text import plural

# ------------------------------------------------------------------- command


@dataclass
class SweepRun:
    """What one `smd sweep` did: the family, its results and the files written."""

    family: Family
    result: FamilyResult | None = None
    metrics: dict[str, np.ndarray] | None = None
    response: FrequencyResponse | None = None
    outputs: list = field(default_factory=list)


def run_and_write(path, out, cli: dict[str, Any], workers: int | None = None, plots: bool = True,
                  progress: bool = False) -> SweepRun:
    """Load, build the family, solve it, write `<stem>_sweep.h5` and the plots; input errors before any work."""
    from smdcli.io.atomic import together
    from smdcli.io.folders import output_folder
    from smdcli.io.sweep_hdf5 import write_sweep

    sc = scenario_mod.load(path)
    spec = read_spec(sc, cli)
    family = build_family(sc, spec)
    if spec.frequency is not None:
        input_index(family.base, spec.input, sc.path)
        if spec.normalized and family.base.n != 1:
            raise UsageError(f"{sc.path}: --normalized needs a 1-DOF scene (X K / F0 against omega / omega_n); "
                             f"this one has {family.base.n} DOFs")
        if not family.base.is_linear or spec.measure:
            for s in {0, len(family) - 1}:
                _driving_force(family.member_scenario(s))
    out_dir = output_folder(out)
    run = SweepRun(family)
    measured = spec.frequency is not None and (not family.base.is_linear or spec.measure)
    total = len(family) * ((2 if spec.direction == "both" else 1) * len(spec.frequency) if measured else 1)
    label = "frequency response" if spec.frequency is not None else "sweeping"
    shown = progress and total > 1
    with bar(label, total, shown) as advance:
        tick = advance if shown else None  # None: workers need not report over a queue
        if spec.frequency is not None:
            run.response = frequency_response(family, workers, tick)
        else:
            run.result = solve_family(family, spec.method, workers, tick)
            run.metrics = metrics(family, run.result)
    took = run.response.wall_time_s if run.response else run.result.wall_time_s
    if run.result is not None:
        how = run.result.how
    elif run.response.measured:
        how = "simulated to steady state (shooting), one task per sweep direction"
    else:
        how = "exact receptance, all members at once"
    with together():  # the files appear together, or none of them
        h5 = out_dir / f"{sc.stem}_sweep.h5"
        write_sweep(h5, family, run.result, run.metrics, run.response, {"how": how, "wall_time_s": took})
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.sweep import frequency_figure, metric_figure, overlay_figure

            title = sc.title or sc.stem
            figures = []
            if run.response is not None:
                figures.append(("frequency", frequency_figure(family, run.response, title, spec.frequency_unit,
                                                                       spec.normalized)))
            else:
                figures.append((spec.quantity, overlay_figure(family, run.result, spec.quantity, title)))
                if len(family) > 1 and spec.kind == "parameter":
                    name = "heatmap" if len(spec.parameters) == 2 else "metric"
                    figures.append((name, metric_figure(family, run.metrics[spec.metric], spec.metric,
                                                                 family.base.dofs, title)))
            for name, figure in figures:
                png = out_dir / f"{sc.stem}_sweep_{name}.png"
                save_figure(figure, png)
                run.outputs.append(png)
    return run


def summary(run: SweepRun) -> dict:
    """What a user wants to read after a sweep, as plain data."""
    family = run.family
    data: dict[str, Any] = {"scenario": family.scenario.path, "kind": family.spec.kind, "members": len(family),
                            "parameters": list(family.spec.parameters), "outputs": [str(p) for p in run.outputs]}
    if run.result is not None:
        data["how"] = run.result.how
        data["wall_time_s"] = run.result.wall_time_s
        data["failed"] = [family.labels[s] + ": " + run.result.messages[s]
                          for s in np.flatnonzero(~run.result.success)]
        metric = run.metrics[family.spec.metric]
        data["metric"] = {"name": family.spec.metric, "units": METRIC_UNITS[family.spec.metric],
                          "per_member": {family.labels[s]: dict(zip(family.base.dofs, map(float, metric[s])))
                                         for s in range(min(len(family), 50))}}
        if family.spec.metric == "settling_time":
            data["metric"]["null_means"] = "not settled within the run"
    if run.response is not None:
        r = run.response
        data["how"] = "exact receptance" if r.exact else "measured by simulation to steady state"
        data["wall_time_s"] = r.wall_time_s
        data["input_dof"] = r.input_dof
        data["peaks"] = r.peaks
        if r.difference is not None:
            data["measured_vs_exact"] = r.difference
        if r.measured:
            data["not_steady"] = {d: int((~v[:, r.omega > 0]).sum()) for d, v in r.steady.items()}
    return data


def format_summary(data: dict) -> str:
    """The summary as a few lines for the terminal."""
    lines = [f"{data['scenario']}: {plural(data['members'], 'member')} "
             f"({data['kind']} sweep) in {data['wall_time_s'] * 1e3:.1f} ms, {data['how']}"]
    for failed in data.get("failed", []):
        lines.append(f"  failed: {failed}")
    if "metric" in data:
        name = data["metric"]["name"]
        for label, values in list(data["metric"]["per_member"].items())[:12]:
            unit = METRIC_UNITS[name]
            cells = ", ".join(f"{dof} = {value:.4g} {unit}" if value is not None and math.isfinite(value)
                              else f"{dof} = {'not settled' if name == 'settling_time' else 'n/a'}"
                              for dof, value in values.items())
            lines.append(f"  {label}: {name} {cells}")
        if data["members"] > 12:
            lines.append(f"  ... {data['members'] - 12} more in the HDF5 file")
    if "peaks" in data:
        lines.append(f"  resonance peaks (unit force on {data['input_dof']}): "
                     + ("none inside the frequency range" if not data["peaks"] else ""))
        for p in data["peaks"][:24]:
            amp = f"{p['amplitude']:.5g} m/N" if math.isfinite(p["amplitude"]) else "unbounded (undamped)"
            how = f" (largest measured, sweep {p['direction']}, on the grid)" if "direction" in p else ""
            who = f"{p['label']}: " if data["members"] > 1 else ""
            lines.append(f"    {who}{p['dof']} at {p['omega']:.6g} rad/s ({p['omega'] / (2 * math.pi):.5g} Hz), "
                         f"{amp}{how}")
        if len(data["peaks"]) > 24:
            lines.append(f"    ... {len(data['peaks']) - 24} more in the HDF5 file")
    if "measured_vs_exact" in data:
        lines.append(f"  simulated to steady state vs exact: largest difference {data['measured_vs_exact']:.2e} of the peak")
    for direction, count in data.get("not_steady", {}).items():
        if count:
            lines.append(f"  sweep {direction}: {count} frequencies did not settle to a period within {MAX_PERIODS} periods")
    lines.append("wrote " + ", ".join(data["outputs"]))
    return "\n".join(lines)
