"""`smd ida`: incremental dynamic analysis of a scene under a suite of records, each scaled to collapse (hunt and
fill, analysis/ida.py), the fractile curves across records and the lognormal fragility of the collapse
intensities; OUT/<stem>_ida.h5, OUT/<stem>_ida.png and OUT/<stem>_fragility.png. A record per task: the process
pool or a Dask scheduler; each finished record is kept in OUT/<stem>_ida.partial/ so that --resume computes
nothing twice.

Must not import: cli.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from smdcli.errors import ScenarioError, UsageError

RECORD_EXTENSIONS = (".at2", ".v2", ".v2c", ".csv", ".txt")


@dataclass
class IdaRun:
    """A campaign's traces, fractiles, fragility and files."""

    scenario: str
    im: object
    edp: object
    collapse: object
    traces: list
    levels: np.ndarray
    fractiles: dict
    fragility: object | None
    wall_time_s: float
    resumed: int = 0
    outputs: list[Path] = field(default_factory=list)


def record_files(given: list[str], where: str) -> list[Path]:
    """The record files named (a folder: its record files, sorted by name); UsageError for none or a missing one."""
    found: list[Path] = []
    for entry in given:
        path = Path(entry)
        if path.is_dir():
            found += sorted(p for p in path.iterdir() if p.suffix.lower() in RECORD_EXTENSIONS and p.is_file())
        elif path.is_file():
            found.append(path)
        else:
            raise UsageError(f"{where} {entry}: no such file or folder")
    if not found:
        raise UsageError(f"{where}: no record files found (.AT2, .V2, .V2c, .csv, .txt)")
    return found


def member_document(doc: dict, record: Path, scale: float, end: float) -> dict:
    """The scenario's document under a record: its [ground_motion] file replaced (an AT2's or COSMOS file's own
    unit, a text file's the scenario's units), scaled, and the run lasting to `end`."""
    table = {key: value for key, value in doc["ground_motion"].items()
             if key not in ("file", "format", "channel", "dt", "scale", "t", "values")}
    if record.suffix.lower() in (".at2", ".v2", ".v2c"):
        table.pop("units", None)
    table.update(type="table", file=str(record.resolve()), scale=scale, quantity="acceleration")
    return {**doc, "ground_motion": table, "time": {**doc["time"], "start": 0.0, "end": end}}


def run_record(task: dict) -> dict:
    """One record's trace, as plain data (a task a process pool or a Dask worker runs)."""
    from smdcli.analysis.ida import (Collapse, Demand, Intensity, demand, over_limit, record_intensity, solved,
                                     trace)

    record = Path(task["record"])
    im, edp, rule = Intensity(**task["im"]), Demand(**task["edp"]), Collapse(**task["collapse"])

    def scene(scale: float, end: float):
        return member_scene(task, scale, end)
    shape = scene(1.0, 1.0).ground_motion.shape
    times, values = np.asarray(shape.t, dtype=float), np.asarray(shape.values, dtype=float)
    own = record_intensity(times, values, im, task["first_period"])
    if not own > 0:
        raise ScenarioError(str(record), None, f"the record's {im.text} is {own:g}: it cannot be scaled to an intensity")
    end = float(times[-1]) + task["tail"]

    def run(scale: float):
        result = solved(scene(scale, end), edp)
        return demand(result, edp), over_limit(result, rule)
    return asdict(trace(str(record), own, run, rule, task["tolerance"], task["runs"]))


def member_scene(task: dict, scale: float, end: float):
    """The scenario under the task's record at this scale, lasting to `end`, validated (ScenarioError naming the
    record)."""
    import tomli_w

    from smdcli.scenario.load import parse_document
    from smdcli.solvers.run import check_solver

    member = member_document(task["doc"], Path(task["record"]), scale, end)
    try:
        return check_solver(parse_document(member, tomli_w.dumps(member), task["scenario"]))
    except ScenarioError as exc:
        raise ScenarioError(exc.file, exc.field, f"under the record {task['record']}: {exc.message}") from None


def ida_command(path: str | Path, out: str | Path, records: list[str] | None = None, im: str | None = None,
                edp: str | None = None, collapse: str | None = None, runs: int | None = None,
                im_tolerance: float | None = None, tail: float | None = None, workers: int | None = None,
                scheduler: str | None = None, resume: bool = False, plots: bool = True, progress: bool = False) -> IdaRun:
    """Read the scene, the options (flags over its [ida] table), run every record's trace, write the outputs."""
    import time

    from smdcli.analysis.fragility import from_collapse_intensities
    from smdcli.analysis.ida import fractiles, read_collapse, read_demand, read_intensity
    from smdcli.io.folders import output_folder
    from smdcli.model import build
    from smdcli.solvers.run import load

    begin = time.perf_counter()
    sc = load(path)
    table = dict(sc.ida)
    if sc.ground_motion is None:
        raise UsageError(f"{sc.path}: smd ida shakes the scene by each record: it needs a [ground_motion] table")
    given = records if records else table.get("records")
    if not given:
        raise UsageError(f"{sc.path}: give --records DIR|FILE (or records = [...] in an [ida] table)")
    files = record_files(list(given), "--records")
    has_building = sc.building is not None
    intensity = read_intensity(im or table.get("im", "sa"))
    if not (edp or "edp" in table or has_building):
        raise UsageError(f"--edp: {sc.path} has no [building] table (storey_heights) for the default max_drift_ratio; "
                         "give --edp peak_displacement:<dof> or peak_acceleration:<dof>")
    demand_spec = read_demand(edp or table.get("edp", "max_drift_ratio"), sc.dof_names, has_building)
    rule = read_collapse(collapse or table.get("collapse"), has_building)
    runs = int(runs if runs is not None else table.get("runs", 12))
    tolerance = float(im_tolerance if im_tolerance is not None else table.get("im_tolerance", 1e-3))
    tail = float(tail if tail is not None else table.get("tail", 5.0))
    if runs < 0 or not (0 < tolerance < 1) or not (tail >= 0 and math.isfinite(tail)):
        raise UsageError("--runs, --im-tolerance, --tail: expected runs >= 0, 0 < im_tolerance < 1, tail >= 0 s")
    model = build(sc)
    omega = [w for w in model.modes.natural_frequencies if w > 0]
    first_period = 2 * math.pi / min(omega) if omega else math.nan
    if intensity.kind == "sa" and intensity.period is None and not omega:
        raise UsageError(f"--im sa: {sc.path} has no vibrating mode (give sa:T=<s>)")
    doc = tomllib.loads(sc.text)
    tasks = [{"doc": doc, "record": str(f), "scenario": sc.path, "im": asdict(intensity), "edp": asdict(demand_spec),
              "collapse": asdict(rule), "first_period": first_period, "tolerance": tolerance, "runs": runs,
              "tail": tail} for f in files]
    for task in tasks:  # every record read and its scene valid before anything is written
        member_scene(task, 1.0, 1.0)
    out_dir = output_folder(out)
    partial = out_dir / f"{sc.stem}_ida.partial"
    done = _resumed(partial, tasks) if resume else {}
    from smdcli.progress import bar

    with bar("records", len(tasks), enabled=progress, transient=True) as advance:
        advance(len(done))
        traces = _run_all(tasks, done, partial, workers, scheduler, advance)
    from smdcli.analysis.ida import Trace

    traces = [Trace(**t) for t in traces]
    limit = rule.drift if demand_spec.kind == "max_drift_ratio" else \
        rule.displacement if demand_spec.kind == "peak_displacement" else None
    levels, curves = fractiles(traces, limit)
    collapsed = np.array([t.collapse_im for t in traces])
    fragility = from_collapse_intensities(collapsed[np.isfinite(collapsed)]) \
        if np.isfinite(collapsed).sum() >= 2 and np.unique(collapsed[np.isfinite(collapsed)]).size >= 2 else None
    run = IdaRun(sc.path, intensity, demand_spec, rule, traces, levels, curves, fragility,
                 time.perf_counter() - begin, len(done))
    from smdcli.io.atomic import together
    from smdcli.io.ida_hdf5 import write_ida

    with together():
        h5 = out_dir / f"{sc.stem}_ida.h5"
        write_ida(h5, run)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.fragility import fragility_figure
            from smdcli.plots.ida import ida_figure

            png = out_dir / f"{sc.stem}_ida.png"
            save_figure(ida_figure(run), png)
            run.outputs.append(png)
            if fragility is not None:
                png = out_dir / f"{sc.stem}_fragility.png"
                save_figure(fragility_figure(fragility, intensity.units, f"{sc.stem}'s collapses"), png)
                run.outputs.append(png)
    for stale in partial.glob("*.json") if partial.is_dir() else ():
        stale.unlink()
    if partial.is_dir():
        partial.rmdir()
    return run


def _identity(task: dict) -> str:
    """What a finished record's result depends on: the task itself (scene, record, options)."""
    return json.dumps({k: v for k, v in task.items() if k != "doc"} | {"doc": json.dumps(task["doc"], sort_keys=True,
                                                                                         default=str)},
                      sort_keys=True, default=str)


def _resumed(partial: Path, tasks: list[dict]) -> dict[int, dict]:
    """The records an interrupted campaign finished, where their task is the same."""
    done = {}
    for i, task in enumerate(tasks):
        kept = partial / f"record_{i:04d}.json"
        if kept.is_file():
            data = json.loads(kept.read_text())
            if data.get("identity") == _identity(task):
                done[i] = data["trace"]
    return done


def _run_all(tasks: list[dict], done: dict[int, dict], partial: Path, workers: int | None,
             scheduler: str | None, advance=None) -> list[dict]:
    """Every record's trace (a finished one's from `done`), each kept in `partial` as it finishes."""
    from smdcli.io.atomic import atomic_path

    partial.mkdir(exist_ok=True)
    results: dict[int, dict] = dict(done)

    def keep(i: int, trace: dict) -> None:
        results[i] = trace
        if advance is not None:
            advance(1)
        with atomic_path(partial / f"record_{i:04d}.json") as tmp:
            tmp.write_text(json.dumps({"identity": _identity(tasks[i]), "trace": trace}))
    todo = [i for i in range(len(tasks)) if i not in results]
    if scheduler is not None:
        from smdcli.commands.ida_dask import run_on_dask

        for i, trace in run_on_dask(scheduler, run_record, [tasks[i] for i in todo], todo):
            keep(i, trace)
    elif (workers or 1) <= 1 or len(todo) <= 1:
        for i in todo:
            keep(i, run_record(tasks[i]))
    else:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(run_record, tasks[i]): i for i in todo}
            for future in as_completed(futures):
                keep(futures[future], future.result())
    return [results[i] for i in range(len(tasks))]


def ida_summary(run: IdaRun) -> dict:
    """The campaign as plain data."""
    f = run.fragility
    return {"scenario": run.scenario, "status": "ok", "exit_code": 0, "im": run.im.text, "im_units": run.im.units,
            "edp": run.edp.text, "edp_units": run.edp.units, "collapse": run.collapse.text,
            "records": [{"record": t.record, "runs": len(t.im), "collapse_im": None if math.isnan(t.collapse_im)
                         else t.collapse_im} for t in run.traces],
            "analyses": sum(len(t.im) for t in run.traces), "resumed_records": run.resumed,
            "fragility": None if f is None else {"theta": f.theta, "beta": f.beta, "theta_95": list(f.theta_95),
                                                 "beta_95": list(f.beta_95)},
            "wall_time_s": run.wall_time_s, "outputs": [str(o) for o in run.outputs]}


def format_ida(d: dict) -> str:
    """Terminal text for a campaign."""
    never = sum(r["collapse_im"] is None for r in d["records"])
    lines = [f"{d['scenario']}: IDA of {len(d['records'])} records, {d['analyses']} runs "
             f"({d['im']} against {d['edp']}; collapse: {d['collapse']})" +
             (f"; {d['resumed_records']} records kept from an interrupted run" if d["resumed_records"] else "")]
    for r in d["records"][:12]:
        at = "never collapsed" if r["collapse_im"] is None else f"collapses at {r['collapse_im']:.5g} {d['im_units']}"
        lines.append(f"  {Path(r['record']).name:<28} {r['runs']:3d} runs, {at}")
    if len(d["records"]) > 12:
        lines.append(f"  ... ({len(d['records'])} records; --json lists every one)")
    if d["fragility"]:
        f = d["fragility"]
        lines.append(f"  fragility theta {f['theta']:.5g} {d['im_units']} (95 % {f['theta_95'][0]:.4g} .. "
                     f"{f['theta_95'][1]:.4g}), beta {f['beta']:.4g} (95 % {f['beta_95'][0]:.4g} .. "
                     f"{f['beta_95'][1]:.4g})" + (f"; {never} records never collapsed, left out" if never else ""))
    if d["outputs"]:
        lines.append(f"  wrote {', '.join(d['outputs'])}")
    return "\n".join(lines)
