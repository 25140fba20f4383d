"""Library entry points behind `smd simulate` and `smd info`: scenario -> model -> solver -> writers.

Must not import: cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.errors import SolverFailed, UsageError
from smdcli.io.folders import output_folder
from smdcli.model import GROUND_DOF, Model, build, time_grid
from smdcli.model.sparse import SPARSE_DOFS
from smdcli.solvers.peaks import result_peaks
from smdcli.result import Result
from smdcli.scenario import Scenario
from smdcli.solvers.run import load as load_checked, failure_message, solve_scenario
from smdcli.strict_json import status


@dataclass(frozen=True)
class Options:
    """Command-line overrides of the scenario's [solver] table, and what to write."""

    method: str | None = None
    rtol: float | None = None
    atol: float | None = None
    plots: bool = True
    save_partial: bool = False  # on a solver failure, write what was computed to <stem>_partial.h5
    strict: bool = False  # a suspect run (its physics broken along the solution) exits 1


@dataclass
class Run:
    """One scenario's trip through smd, with the files it produced."""

    scenario: Scenario
    model: Model
    result: Result
    outputs: list[Path] = field(default_factory=list)
    checks: tuple = ()  # the [[expect]] verdicts (commands.expect.Check)
    strict: bool = False  # --strict: a suspect run exits 1


def prepare(path: str | Path) -> tuple[Scenario, Model, np.ndarray]:
    """Load, validate and assemble: every input error surfaces here, before any work."""
    sc = load_checked(path)
    return sc, build(sc), time_grid(sc.time)


def solve_run(sc: Scenario, model: Model, grid: np.ndarray, options: Options = Options()) -> Result:
    """Solve a scenario as `smd simulate` does: with its element forces and energy balance where it succeeded."""
    result = solve_scenario(sc, model, grid, options.method, options.rtol, options.atol)
    if result.success:
        from smdcli.analysis.energy import with_physics
        from smdcli.analysis.guards import suspicions

        result = with_physics(model, result)
        reasons = suspicions(model, result)
        if reasons:
            from dataclasses import replace

            result = result.changed(stats=replace(result.stats, suspect="; ".join(reasons)),
                                    notes=(*result.notes, *(f"warning: suspect: {reason}" for reason in reasons)))
    result = result.changed(origin=(sc, model))
    if result.success and sc.building is not None:
        from smdcli.analysis.storeys import storeys

        result = result.changed(storeys=storeys(result, sc.building))
    return result


def simulate(path: str | Path, out: str | Path, options: Options = Options()) -> Run:
    """Validate, solve and write one scenario; a solver failure raises SolverFailed and writes nothing."""
    sc, model, grid = prepare(path)
    out_dir = output_folder(out, make=False)  # made when its files are written
    result = solve_run(sc, model, grid, options)
    if sc.sweep:
        note = ("this file's [sweep] table was not run: simulate solved the scene as written "
                f"(its base member); `smd sweep {sc.path}` runs the family")
        result = result.changed(notes=(note, *result.notes))
    run = Run(sc, model, result, strict=options.strict)
    from smdcli.io.hdf5 import write_simulation

    if result.success and sc.expect:
        from smdcli.commands.expect import evaluate

        run.checks = evaluate(sc.expect, model, result)

    if not result.success:
        message = failure_message(sc, model, result)
        if options.save_partial:
            partial = out_dir / f"{sc.stem}_partial.h5"
            write_simulation(partial, sc, model, result)
            message += f"; what was computed (to t = {result.t_failed:g} s, NaN after) is in {partial}, marked failed"
        raise SolverFailed(message, result=result)

    from smdcli.io.atomic import together

    with together():  # the run's files appear together, or none of them
        h5 = out_dir / f"{sc.stem}.h5"
        write_simulation(h5, sc, model, result, [check.as_dict() for check in run.checks])
        run.outputs.append(h5)
        if options.plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.response import phase_figure, response_figure

            title = sc.title or sc.stem
            from smdcli.plots.energy import energy_figure

            for name, figure in (("response", response_figure), ("phase", phase_figure), ("energy", energy_figure)):
                png = out_dir / f"{sc.stem}_{name}.png"
                save_figure(figure(result, title), png)
                run.outputs.append(png)
    return run


def summary(run: Run) -> dict:
    """The facts a user wants after a run, as plain data (printed, or as JSON)."""
    s = run.result.stats
    failed = sum(not check.passed for check in run.checks)
    suspect = bool(s.suspect)
    return {
        "scenario": run.scenario.path,
        "status": "expect failed" if failed else "suspect" if suspect else "ok",
        "exit_code": 1 if failed or (suspect and run.strict) else 0,
        "suspect": [reason for reason in s.suspect.split("; ") if reason],
        "title": run.scenario.title,
        "method": s.method,
        "requested_method": s.requested_method,
        "reason": s.reason,
        "rtol": s.rtol, "atol": s.atol, "dt": s.dt,
        "steps_accepted": s.steps_accepted, "steps_rejected": s.steps_rejected,
        "nfev": s.nfev, "njev": s.njev, "nlu": s.nlu,
        "wall_time_s": s.wall_time_s,
        "success": s.success, "message": s.message,
        "peak_displacement_m": dict(zip(run.result.dofs, map(float, result_peaks(run.result, absolute=False)))),
        "energy_residual": None if run.result.energy is None else run.result.energy.max_relative_residual,
        **_storey_summary(run.result.storeys),
        "notes": list(run.result.notes),
        "expect": [check.as_dict() for check in run.checks],
        "outputs": [str(p) for p in run.outputs],
    } | ({} if run.result.ground is None else {"peak_absolute_displacement_m": dict(zip(
        run.result.dofs, map(float, result_peaks(run.result, absolute=True))))}) \
      | ({} if run.result.nonsmooth is None else _events(run.result.nonsmooth))


def _events(history) -> dict:
    """The events of a run with nonsmooth elements: their count by kind, and each (time, element, kind)."""
    counts: dict[str, int] = {}
    for _, _, kind in history.events:
        counts[kind] = counts.get(kind, 0) + 1
    return {"event_counts": counts,
            "events": [{"time": t, "element": element, "kind": kind} for t, element, kind in history.events]}


def _storey_summary(storeys) -> dict:
    """A [building]'s storeys in the summary: each storey's peak drift ratio and drift, residual drift, peak shear."""
    if storeys is None:
        return {}
    return {"storeys": [{"storey": name, "peak_drift_ratio": float(ratio), "peak_drift_m": float(drift),
                         "residual_drift_m": float(residual), "peak_shear_n": float(shear)}
                        for name, ratio, drift, residual, shear in zip(storeys.names, storeys.peak_drift_ratio,
                                                                       storeys.peak_drift, storeys.residual_drift,
                                                                       storeys.peak_shear)]}


def failed_summary(path: str | Path, message: str | None, exit_code: int | None) -> dict:
    """The JSON entry of a file that failed (its one-line message and exit code), or was not run after
    --fail-fast stopped (None, None)."""
    return {"scenario": str(path), "status": status(exit_code), "exit_code": exit_code, "success": False,
            "message": message or "not run: an earlier file failed (--fail-fast)", "outputs": []}


def format_summary(data: dict) -> str:
    """Terminal text for a run summary."""
    lines = [f"{data['scenario']}: {data['title']}" if data["title"] else data["scenario"],
             f"  method   {data['method']} ({data['reason']})"]
    if data["method"] == "sparse_newmark":  # fixed steps, chosen to meet the tolerance
        lines.append(f"  tolerance rtol={data['rtol']:g} atol={data['atol']:g}, met by the error estimate; finest "
                     f"step {data['dt']:g} s")
    elif data.get("dt") is not None and data["dt"] == data["dt"]:  # a fixed step: no tolerance was used
        lines.append(f"  step     dt = {data['dt']:g} s, fixed (rtol and atol do not apply)")
    elif data["rtol"] is not None:
        lines.append(f"  tolerance rtol={data['rtol']:g} atol={data['atol']:g}")
    rejected = "not reported" if data["steps_rejected"] < 0 else data["steps_rejected"]
    lines.append(f"  cost     {data['steps_accepted']} steps ({rejected} rejected), {data['nfev']} f evals, "
                 f"{data['njev']} Jacobians, {data['nlu']} LU; {data['wall_time_s'] * 1e3:.1f} ms")
    items = list(data["peak_displacement_m"].items())
    shown, largest = listed(items, lambda value: value)
    peaks = ", ".join(f"{k} {v:.6g}" for k, v in shown)
    if len(shown) < len(items):
        name, top = largest
        peaks += f" m, ... ({len(items)} DOFs; the largest, {top:.6g} m, at {name}; --json lists every one)"
    else:
        peaks += " m"
    if "peak_absolute_displacement_m" in data:
        lines.append(f"  peak |x| {peaks} relative to the ground")
        top = data["peak_absolute_displacement_m"]
        lines.append(f"  absolute {', '.join(f'{k} {v:.6g}' for k, v in list(top.items())[:SHOWN])} m"
                     + (" ..." if len(top) > SHOWN else ""))
    else:
        lines.append(f"  peak |x| {peaks}")
    if "event_counts" in data:
        counts = data["event_counts"]
        told = ", ".join(f"{count} {kind}" for kind, count in counts.items())
        lines.append(f"  events   {sum(counts.values())}" + (f" ({told})" if told else "")
                     + (f"; the last at t = {data['events'][-1]['time']:.6g} s ({data['events'][-1]['element']} "
                        f"{data['events'][-1]['kind']})" if data["events"] else ""))
    if data.get("storeys"):
        shown = data["storeys"][:SHOWN]
        lines.append("  drift    peak ratio " + ", ".join(f"{s['storey']} {s['peak_drift_ratio']:.4g}" for s in shown)
                     + (" ..." if len(data["storeys"]) > SHOWN else "") + " (storey drift over height)")
    if data.get("energy_residual") is not None:
        lines.append(f"  energy   balance residual {data['energy_residual']:.2g} of the largest energy "
                     "(the run's physical accuracy check)")
    lines += [f"  {note}" for note in data["notes"]]
    if data.get("expect"):
        from smdcli.commands.expect import check_line

        lines += [f"  expect   {check_line(check)}" for check in data["expect"]]
    if data["outputs"]:
        lines.append(f"  wrote    {', '.join(data['outputs'])}")
    return "\n".join(lines)


def info(path: str | Path, state_space: Path | None = None) -> dict:
    """DOFs, matrices, modes, regimes, stiffness and auto's choice, as plain data; with state_space, A B C D
    written there too."""
    sc, model, grid = prepare(path)
    if state_space is not None:
        from smdcli.io.state_space import write_state_space

        if model.is_sparse:
            raise UsageError(f"--state-space: {sc.path} is a sparse scene of {model.n} DOFs; its state matrix "
                             f"would hold (2n)^2 = {4 * model.n ** 2:.3g} numbers; expected at most "
                             f"{SPARSE_DOFS} masses")
        write_state_space(state_space, model)
    m = model.modes
    from smdcli.solvers.auto import Auto

    solver, reason = Auto().choose(model, grid, sc.solver.rtol)
    # participation in a ground motion moving every DOF alike (r = ones): Gamma = phi^T M r of the mass-normalised
    # undamped shapes, effective mass Gamma^2, which sum to the total mass
    gamma = m.shapes.T @ (model.M @ np.ones(model.n))
    total_mass = float(model.M.sum())
    data = {
        "scenario": sc.path, "title": sc.title, "dofs": list(model.dofs),
        "form": "element" if model.element_form else "matrix",
        "M": _listed(model.M), "C": _listed(model.C), "K": _listed(model.K),
        # with hysteretic springs, K holds only their always-present part; at rest (the modes') they are elastic
        **({"K_initial": model.initial_K.tolist()} if model.initial_K is not model.K else {}),
        "linear": model.is_linear, "nonlinear_elements": list(model.nonlinear_paths),
        "forces": [f"{p} on {model.dofs[d]}: {kind}"
                   for p, kind, d in zip(model.force_paths, model.force_types, model.force_dofs) if d != GROUND_DOF],
        "modes": [
            {"natural_frequency_rad_s": float(w), "natural_frequency_hz": float(w / (2 * math.pi)),
             "damping_ratio": float(z), "regime": r, "participation": float(g), "effective_mass": float(g * g),
             "effective_mass_ratio": float(g * g / total_mass)}
            for w, z, r, g in zip(m.natural_frequencies, m.damping_ratios, m.regimes, gamma)
        ],
        "eigenvalues": [[float(e.real), float(e.imag)] for e in m.eigenvalues],
        # a sparse scene's modes are its lowest few: its spread of decay rates is not known
        "stiffness_ratio": None if model.is_sparse else model.stiffness_ratio,
        "stiff": None if model.is_sparse else model.is_stiff,
        "time": {"start": float(grid[0]), "end": float(grid[-1]), "points": len(grid)},
    }
    if model.is_sparse:
        data["modes_listed"] = f"the lowest {len(m.natural_frequencies)} of {model.n}"
    if model.ground is not None:
        data["ground_motion"] = {"quantity": model.ground.quantity, "type": model.ground.kind,
                                 "jumps": len(model.ground.jumps),
                                 "coordinates": "relative to the ground (absolute_* in the result file)"}
    if state_space is not None:
        data["state_space"] = str(state_space)
    if solver is not None:
        data["auto"] = {"method": solver.name, "reason": reason}
    else:
        y0 = np.concatenate([model.x0, model.v0])
        lam = np.linalg.eigvals(model.jacobian(0.0, y0))
        re = np.abs(lam.real[lam.real < 0])
        ratio0 = float(re.max() / re.min()) if len(re) else 1.0
        data["linearized_at_start"] = {"eigenvalues": [[float(e.real), float(e.imag)] for e in lam],
                                       "stiffness_ratio": ratio0}
        from smdcli.solvers.integrators.taylor_series import Taylor

        unsupported = Taylor.unsupported(model)
        explicit = "DOP853" if unsupported else "taylor"
        why = f" (no Taylor series for {unsupported})" if unsupported else ""
        data["auto"] = {"method": f"{explicit} or Radau",
                        "reason": (f"nonlinear ({', '.join(model.nonlinear_paths)}): the linearization at the start "
                                   f"has stiffness ratio {ratio0:.3g}, but stiffness is decided along the trajectory: "
                                   f"{explicit}{why} runs while h*|lambda|max stays below its stability limit, "
                                   "else Radau")}
    return data


def _listed(matrix) -> list | dict:
    """A matrix as JSON takes it: rows of numbers, or a sparse scene's nonzeros as coordinates (its n^2 zeros are
    gigabytes of text)."""
    if isinstance(matrix, np.ndarray):
        return matrix.tolist()
    entries = matrix.tocoo()
    return {"shape": list(entries.shape), "rows": entries.row.tolist(), "columns": entries.col.tolist(),
            "values": entries.data.tolist()}


SHOWN = 12  # DOFs, matrix rows and modes `smd info` writes out on a terminal; beyond, a summary


def listed(items: list, size) -> tuple[list, tuple | None]:
    """A terminal's list of a model's DOFs ((name, value) items): every one up to SHOWN; beyond (a large model's
    are for --json or the file), the first SHOWN // 2 and the item of the largest size(value), that item also
    returned (None where every one is listed or no value has a size: size gives None for those)."""
    if len(items) <= SHOWN:
        return items, None
    sized = [item for item in items if size(item[1]) is not None]
    return items[:SHOWN // 2], max(sized, key=lambda item: size(item[1])) if sized else None


def format_info(d: dict) -> str:
    """Terminal text for `smd info`."""
    def matrix(name, rows):
        if isinstance(rows, dict):  # a sparse scene's, as coordinates
            n = rows["shape"][0]
            return f"  {name} =  {n} x {n}, {len(rows['values'])} nonzero (sparse; --json lists them as coordinates)"
        if len(rows) > SHOWN:  # a large model's matrices are for --json or the HDF5 file, not a terminal
            values = np.asarray(rows)
            kind = "diagonal" if np.count_nonzero(values) == np.count_nonzero(np.diag(values)) else "sparse" \
                if np.count_nonzero(values) < 0.1 * values.size else "dense"
            return f"  {name} =  {len(rows)} x {len(rows)}, {np.count_nonzero(values)} nonzero ({kind}; --json has it)"
        body = "\n".join("      [" + ", ".join(f"{v:10.4g}" for v in row) + "]" for row in rows)
        return f"  {name} =\n{body}"

    dofs = d["dofs"] if len(d["dofs"]) <= SHOWN else d["dofs"][:SHOWN // 2] + ["..."] + d["dofs"][-2:]
    lines = [f"{d['scenario']}: {d['title']}" if d["title"] else d["scenario"],
             f"  DOFs     {', '.join(dofs)} ({len(d['dofs'])} DOF{'s' if len(d['dofs']) != 1 else ''}, {d['form']} form, "
             f"{'linear' if d['linear'] else 'nonlinear: ' + ', '.join(d['nonlinear_elements'])})",
             f"  time     {d['time']['start']:g} .. {d['time']['end']:g} s, {d['time']['points']} points"]
    ground = d.get("ground_motion")
    lines += [f"  force    {f}" for f in d["forces"]] or ([] if ground else ["  force    none (free response)"])
    if ground:
        lines.append(f"  ground   {ground['type']} {ground['quantity']}"
                     + (f", {ground['jumps']} jump(s)" if ground["jumps"] else "")
                     + "; x, v, a relative to the ground")
    lines += [matrix("M", d["M"]), matrix("C", d["C"]),
              matrix("K (at rest, the hysteretic springs elastic: the modes')", d["K_initial"]) if "K_initial" in d
              else matrix("K", d["K"])]
    lines.append("  modes    omega_n [rad/s]   f_n [Hz]   zeta        regime           Gamma   M_eff/M")
    for i, mode in enumerate(d["modes"], 1):
        if SHOWN // 2 < i <= len(d["modes"]) - SHOWN // 2:
            if i == SHOWN // 2 + 1:
                lines.append(f"    ... {len(d['modes']) - 2 * (SHOWN // 2)} more modes (--json lists them all)")
            continue
        lines.append(f"    {i:<5}  {mode['natural_frequency_rad_s']:14.6g} {mode['natural_frequency_hz']:10.4g}"
                     f"   {'-' if mode['regime'] == 'rigid-body' else format(mode['damping_ratio'], '<10.5g'):<10}"
                     f"  {mode['regime']:<17}{mode['participation']:9.4g}  {mode['effective_mass_ratio']:6.1%}")
    if "modes_listed" in d:
        lines.append(f"    ({d['modes_listed']} modes: a sparse scene's)")
    if d["stiffness_ratio"] is None:
        lines.append("  stiffness ratio not computed: a sparse scene's needs every mode")
    else:
        lines.append(f"  stiffness ratio {d['stiffness_ratio']:.4g} ({'stiff' if d['stiff'] else 'not stiff'}"
                     f"{' in its linear part' if not d['linear'] else ''})")
    if "linearized_at_start" in d:
        lines.append(f"  linearized at t0: stiffness ratio {d['linearized_at_start']['stiffness_ratio']:.4g}")
    lines.append(f"  auto     {d['auto']['method']}: {d['auto']['reason']}")
    if "state_space" in d:
        lines.append(f"  wrote    {d['state_space']} (A, B, C, D, x0 and the names of states, inputs and outputs)")
    return "\n".join(lines)
