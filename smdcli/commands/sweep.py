"""`smd sweep`: load, build the family, solve it, write `<stem>_sweep.h5` and the plots; summaries.

Must not import: cli."""

from __future__ import annotations

from pathlib import Path

import math
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from smdcli import interrupts
from smdcli.solvers.run import load as load_checked
from smdcli.errors import UsageError
from smdcli.progress import bar
from smdcli.sweep.family import Family, build_family
from smdcli.sweep.frequency import FrequencyResponse, _driving_force, frequency_response, input_index
from smdcli.sweep.shooting import MAX_PERIODS
from smdcli.sweep.spec import METRIC_UNITS, QUANTITIES, read_spec
from smdcli.text import plural

# ------------------------------------------------------------------- command


LISTED = 50  # members a summary names (metrics, failures); the HDF5 file holds them all


@dataclass
class SweepRun:
    """What one `smd sweep` did: the family, what its members gave (a summary's worth) and the files written."""

    family: Family
    keep: str = "full"
    how: str = ""
    methods: set = field(default_factory=set)  # the methods the members were solved by (the plots' titles)
    wall_time_s: float = 0.0
    failed: list[str] = field(default_factory=list)  # "label: message" of the first LISTED failed members
    failed_count: int = 0
    metric: np.ndarray | None = None  # (S, n): the spec's metric of every member
    traces: dict = field(default_factory=dict)  # member -> (time, quantity, success): the overlay's lines
    response: FrequencyResponse | None = None
    resumed_from: int = 0  # members a partial file already held
    restarted: str = ""  # why --resume could not read the partial file back and started over
    outputs: list = field(default_factory=list)
    replaced: str = ""  # what an earlier <stem>_sweep.h5 of another kind held, and the stale plots removed


def run_and_write(path, out, cli: dict[str, Any], workers: int | None = None, plots: bool = True,
                  progress: bool = False, keep: str | None = None, resume: bool = False,
                  scheduler: str | None = None) -> SweepRun:
    """Load, build the family, solve it, write `<stem>_sweep.h5` and the plots; input errors before any work."""
    from smdcli.io.atomic import together
    from smdcli.io.folders import output_folder

    sc = load_checked(path)
    spec = read_spec(sc, cli)
    family = build_family(sc, spec)
    if spec.frequency is not None:
        if keep is not None or resume or scheduler is not None:
            raise UsageError(f"{sc.path}: --keep, --resume and --scheduler are for time-domain sweeps, not a "
                             "frequency response")
        input_index(family.base, spec.input, sc.path)
        if spec.normalized and family.base.n != 1:
            raise UsageError(f"{sc.path}: --normalized needs a 1-DOF scene (X K / F0 against omega / omega_n); "
                             f"this one has {family.base.n} DOFs")
        if not family.base.is_linear or spec.measure:
            for s in {0, len(family) - 1}:
                _driving_force(family.member_scenario(s))
    elif scheduler not in (None, "local"):
        from smdcli.sweep.cluster import check_address

        check_address(scheduler)  # before the output folder is made: an address smd cannot use writes nothing
    out_dir = output_folder(out)
    run = SweepRun(family)
    earlier = _earlier_kind(out_dir / f"{sc.stem}_sweep.h5")
    with together():  # the files appear together, or none of them
        if spec.frequency is not None:
            _frequency_response(run, out_dir, workers, progress)
        else:
            _time_family(run, out_dir, spec.method, keep, resume, workers, progress, scheduler)
        if plots:
            _plots(run, out_dir, spec)
    _remove_stale_plots(run, out_dir, sc.stem, earlier)
    return run


def _earlier_kind(h5: Path) -> str | None:
    """What sweep an existing <stem>_sweep.h5 holds (its sweep_kind: frequency, parameter, ...), or None."""
    import h5py

    if not h5.exists():
        return None
    try:
        with h5py.File(h5, "r") as f:
            return str(f.attrs.get("sweep_kind", "sweep"))
    except OSError:
        return "sweep"


def _remove_stale_plots(run: SweepRun, out_dir: Path, stem: str, earlier: str | None) -> None:
    """The plots of the sweep whose <stem>_sweep.h5 this run replaced, not written again by it, are stale: removed,
    and the summary says what was replaced (a parameter sweep into a folder holding a frequency response left its
    magnitude-and-phase plot beside a file that no longer held it)."""
    if earlier is None:
        return
    written = {Path(p).name for p in run.outputs}
    stale = sorted(p for p in out_dir.glob(f"{stem}_sweep_*.png") if p.name not in written)
    for path in stale:
        path.unlink(missing_ok=True)
    kind = "frequency" if run.response is not None else run.family.spec.kind
    if stale or earlier != kind:
        run.replaced = (f"{out_dir / f'{stem}_sweep.h5'} held a {earlier} sweep, now this {kind} sweep"
                        + (f"; its plots removed: {', '.join(p.name for p in stale)}" if stale else ""))


def _frequency_response(run: SweepRun, out_dir, workers, progress: bool) -> None:
    from smdcli.io.sweep_hdf5 import write_sweep

    family, spec = run.family, run.family.spec
    measured = not family.base.is_linear or spec.measure
    total = len(family) * ((2 if spec.direction == "both" else 1) * len(spec.frequency) if measured else 1)
    shown = progress and total > 1
    with bar("frequency response", total, shown) as advance:
        run.response = frequency_response(family, workers, advance if shown else None)
    if run.response.measured:
        run.how = "simulated to steady state (shooting), one task per sweep direction"
    else:
        run.how = "exact receptance, all members at once"
    run.wall_time_s = run.response.wall_time_s
    h5 = out_dir / f"{family.scenario.stem}_sweep.h5"
    write_sweep(h5, family, run.response, {"how": run.how, "wall_time_s": run.wall_time_s})
    run.outputs.append(h5)


def _time_family(run: SweepRun, out_dir, method: str | None, keep: str | None, resume: bool, workers,
                 progress: bool, scheduler: str | None = None) -> None:
    """Solve the family chunk by chunk, each chunk's rows written as it finishes to `<stem>_sweep.partial.h5`,
    renamed `<stem>_sweep.h5` when complete; an interrupted run leaves the partial file for --resume. Chunks are
    solved here, or on a Dask cluster with a scheduler."""
    from smdcli.io.sweep_hdf5 import DamagedPartial, IncompatiblePartial, SweepFile
    from smdcli.sweep.stream import chunk_plan, identity

    family = run.family
    grid, length = family.output_grid()
    keep = keep or "full"
    _check_disk(out_dir, family, keep, length)
    plan = chunk_plan(family, length)
    final = out_dir / f"{family.scenario.stem}_sweep.h5"
    partial = final.with_name(f"{family.scenario.stem}_sweep.partial.h5")
    digest = identity(family, method, keep)
    if resume and not partial.exists():
        raise UsageError(f"--resume: no {partial} to finish (it is left by an interrupted sweep into {out_dir})")
    with _cluster(scheduler, workers) as cluster:  # reached before any file is written: unreachable is exit 2
        stream = None
        if resume:
            try:
                stream = SweepFile.resume(partial, family, keep, digest)
            except IncompatiblePartial as exc:
                raise UsageError(str(exc)) from None
            except DamagedPartial as exc:
                run.restarted = str(exc)
        if stream is None:
            stream = SweepFile.create(partial, family, keep, grid, length, digest)
        try:
            for members in plan:
                if members.start < stream.done < members.stop:  # a plan is a function of the family: chunks line up
                    raise UsageError(f"{partial}: members_done {stream.done} is inside a chunk; run without "
                                     "--resume to start over")
            run.keep, run.resumed_from = keep, stream.done
            run.metric = np.full((len(family), family.base.n), np.nan)
            if stream.done:
                _recall(run, stream)
            _solve_chunks(run, stream, plan, method, workers, grid, length, progress, cluster, partial, final)
        finally:
            stream.close()
    run.outputs.append(final)


@contextmanager
def _cluster(scheduler: str | None, workers: int | None):
    """The Dask cluster a scheduler names (closed at the end), or None: chunks are solved in this process."""
    if scheduler is None:
        yield None
        return
    from smdcli.sweep.cluster import Cluster

    cluster = Cluster(scheduler, workers)
    try:
        yield cluster
    finally:
        cluster.close()


def _solve_chunks(run: SweepRun, stream, plan: list[range], method, workers, grid, length: int, progress: bool,
                  cluster, partial, final) -> None:
    """The chunks after the stream's members_done, solved and handed to one writer thread, which writes chunk k
    (h5py releases the GIL) while chunk k + 1 is solved: at most two chunks are held, so memory is bounded by
    the chunk, not the sweep. The file is complete and renamed at the end; an interrupt leaves whole chunks."""
    import time
    from concurrent.futures import ThreadPoolExecutor

    from smdcli.io.atomic import resumable_path
    from smdcli.sweep.members import solve_family
    from smdcli.sweep.stream import chunk_buffers

    family, S = run.family, len(run.family)
    todo = [(k, members) for k, members in enumerate(plan) if members.start >= stream.done]
    started = time.perf_counter()
    writer = ThreadPoolExecutor(max_workers=1)
    writing: list = []

    def make_room() -> None:  # at most two chunks held: the one being written and the one being solved
        if len(writing) == 2:
            interrupts.result(writing.pop(0))

    try:
        with resumable_path(partial, final):
            shown = progress and S > 1
            with bar("sweeping", S, shown) as advance:
                if stream.done:
                    advance(stream.done)
                if cluster is None:
                    buffers = [chunk_buffers(family, plan, length) for _ in range(2)]  # reused: see solve_family
                    for k, members in todo:
                        make_room()  # and so the buffers about to be reused are on disk
                        result = solve_family(family.take(members), method, workers, advance if shown else None,
                                              buffers[k % 2])
                        writing.append(interrupts.submit(writer, _measure_and_write, run, stream, members, result, grid,
                                                        length))
                else:
                    for chunk in cluster.chunks(family, [m for _, m in todo], method, run.keep, grid, length,
                                                family.spec.quantity, advance if shown else None):
                        make_room()
                        writing.append(interrupts.submit(writer, _write_chunk, run, stream, chunk))
                for pending in writing:
                    interrupts.result(pending)
            run.wall_time_s = time.perf_counter() - started
            if cluster is not None:
                run.how = f"Dask tasks on {cluster.where}, each chunk in {run.how}"
            chunks = f", in {plural(len(plan), 'chunk')} of up to {len(plan[0])}" if len(plan) > 1 else ""
            run.how = f"{run.how} over {plural(S, 'member')}{chunks}"
            stream.finish({"how": run.how, "wall_time_s": run.wall_time_s})
    except KeyboardInterrupt as exc:
        _settle(writing)  # the chunks being written finish: members_done counts whole chunks
        exc.add_note(f"{stream.done} of {S} members are in {partial}; the same command with --resume finishes it")
        raise
    except BaseException:
        _settle(writing)
        raise
    finally:
        with interrupts.deferred(raise_after=False):
            writer.shutdown()


def _settle(writing: list) -> None:
    """Wait for chunks still being written, whatever interrupts the wait."""
    for pending in writing:
        interrupts.settled(pending)


def _measure_and_write(run: SweepRun, stream, members: range, result, grid, length: int) -> None:
    """A solved chunk measured, appended to the file and noted for the summary (on the writer thread)."""
    from smdcli.sweep.stream import measure_chunk

    _write_chunk(run, stream, measure_chunk(run.family, members, result, run.keep, grid, length,
                                            run.family.spec.quantity))


def _write_chunk(run: SweepRun, stream, chunk) -> None:
    """A measured chunk appended to the file and noted for the summary (on the writer thread)."""
    stream.append(chunk)
    _note(run, chunk)


def _note(run: SweepRun, chunk) -> None:
    """Keep what the summary and the plots need from a chunk."""
    family = run.family
    run.how = chunk.how
    run.methods.update(chunk.methods)
    failed = np.flatnonzero(~chunk.success)
    run.failed_count += len(failed)
    for row in failed[:max(0, LISTED - len(run.failed))]:
        s = chunk.start + int(row)
        run.failed.append(f"{family.labels[s]}: {chunk.messages[row]}")
    run.metric[chunk.start:chunk.start + len(chunk)] = chunk.metrics[family.spec.metric]
    run.traces.update(chunk.traces)


def _recall(run: SweepRun, stream) -> None:
    """What the summary and plots need from the members a resumed partial file already holds."""
    from smdcli.sweep.stream import drawn_members

    f, done, family = stream.f, stream.done, run.family
    run.metric[:done] = f[f"metrics/{family.spec.metric}"][:done]
    success = f["success"][:done]
    failed = np.flatnonzero(~success)
    run.failed_count = len(failed)
    messages = f["message"]
    run.failed = [f"{family.labels[s]}: {messages[s].decode()}" for s in failed[:LISTED]]
    if family.spec.quantity in f:
        time = f["time"]
        for s in drawn_members(len(family)):
            if s < done:
                t = time[()] if time.ndim == 1 else time[s]
                run.traces[int(s)] = (t, f[family.spec.quantity][s], bool(success[s]))


def _check_disk(out_dir, family, keep: str, length: int) -> None:
    """Refuse, before any work, histories the output folder's disk cannot hold; say what --keep metrics needs."""
    import shutil

    if keep != "full":
        return
    histories = len(QUANTITIES) * len(family) * length * family.base.n * 8
    metrics_only = len(family) * (len(METRIC_UNITS) * family.base.n * 8 + 64)
    free = shutil.disk_usage(out_dir).free
    if histories > 0.9 * free:
        raise UsageError(f"{len(family)} members x {length} time points x {family.base.n} DOFs of histories need "
                         f"{_size(histories)}, more than the {_size(free)} free in {out_dir}; --keep metrics stores "
                         f"the metrics alone in about {_size(metrics_only)}")


def _size(count: float) -> str:
    """A byte count for people: 3 significant digits and a decimal unit."""
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if count < 1000 or unit == "TB":
            return f"{count:.3g} {unit}"
        count /= 1000


def _plots(run: SweepRun, out_dir, spec) -> None:
    from smdcli.plots.common import save_figure
    from smdcli.plots.sweep import frequency_figure, metric_figure, overlay_figure

    family = run.family
    title = family.scenario.title or family.scenario.stem
    figures = []
    if run.response is not None:
        figures.append(("frequency", frequency_figure(family, run.response, title, spec.frequency_unit,
                                                               spec.normalized)))
    else:
        solved = ", ".join(sorted(run.methods)) or "exact"
        solved = "each solved exactly" if solved == "exact" else f"solved by {solved}"
        figures.append((spec.quantity, overlay_figure(family, run.traces, family.base.dofs, spec.quantity, title,
                                                      solved)))
        if len(family) > 1 and spec.kind == "parameter":
            name = "heatmap" if len(spec.parameters) == 2 else "metric"
            figures.append((name, metric_figure(family, run.metric, spec.metric, family.base.dofs, title)))
    for name, figure in figures:
        png = out_dir / f"{family.scenario.stem}_sweep_{name}.png"
        save_figure(figure, png)
        run.outputs.append(png)


def summary(run: SweepRun) -> dict:
    """What a user wants to read after a sweep, as plain data."""
    family = run.family
    data: dict[str, Any] = {"scenario": family.scenario.path, "kind": family.spec.kind, "members": len(family),
                            "parameters": list(family.spec.parameters), "outputs": [str(p) for p in run.outputs],
                            "how": run.how, "wall_time_s": run.wall_time_s}
    if run.replaced:
        data["replaced"] = run.replaced
    if run.response is None:
        data["keep"] = run.keep
        if run.resumed_from:
            data["resumed_from"] = run.resumed_from
        if run.restarted:
            data["restarted"] = run.restarted
        data["failed"] = run.failed
        data["failed_count"] = run.failed_count
        data["metric"] = {"name": family.spec.metric, "units": METRIC_UNITS[family.spec.metric],
                          "per_member": {family.labels[s]: dict(zip(family.base.dofs, map(float, run.metric[s])))
                                         for s in range(min(len(family), LISTED))}}
        if family.spec.metric == "settling_time":
            data["metric"]["null_means"] = "not settled within the run"
    else:
        r = run.response
        data["how"] = ("exact transmissibility (ground displacement)" if r.ground else "exact receptance"
                       if r.exact else "measured by simulation to steady state")
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
    if data.get("keep") == "metrics":
        lines.append("  kept: the metrics and status of each member (--keep metrics), no time histories")
    if data.get("resumed_from"):
        lines.append(f"  resumed: {data['resumed_from']} members were already done")
    if data.get("restarted"):
        lines.append(f"  started over: {data['restarted']}")
    if data.get("replaced"):
        lines.append(f"  replaced: {data['replaced']}")
    for failed in data.get("failed", []):
        lines.append(f"  failed: {failed}")
    if data.get("failed_count", 0) > len(data.get("failed", [])):
        lines.append(f"  ... {data['failed_count'] - len(data['failed'])} more failed (see success and message in "
                     "the HDF5 file)")
    if "metric" in data:
        name = data["metric"]["name"]
        from smdcli.commands.simulate import listed

        for label, values in list(data["metric"]["per_member"].items())[:12]:
            unit = METRIC_UNITS[name]
            items = list(values.items())
            shown, largest = listed(items, lambda value: value if value is not None and math.isfinite(value) else None)
            cells = ", ".join(f"{dof} = {value:.4g} {unit}" if value is not None and math.isfinite(value)
                              else f"{dof} = {'not settled' if name == 'settling_time' else 'n/a'}"
                              for dof, value in shown)
            if len(shown) < len(items):
                top = f"; the largest, {largest[1]:.4g} {unit}, at {largest[0]}" if largest is not None else ""
                cells += f", ... ({len(items)} DOFs{top}; --json lists every one)"
            lines.append(f"  {label}: {name} {cells}")
        if data["members"] > 12:
            lines.append(f"  ... {data['members'] - 12} more in the HDF5 file")
    if "peaks" in data:
        ground = data["input_dof"] == "ground"
        lines.append(f"  resonance peaks ({'transmissibility |X / U|' if ground else 'unit force on ' + data['input_dof']}): "
                     + ("none inside the frequency range" if not data["peaks"] else ""))
        for p in data["peaks"][:24]:
            amp = f"{p['amplitude']:.5g}{'' if ground else ' m/N'}" if math.isfinite(p["amplitude"]) \
                else "unbounded (undamped)"
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
