"""Exact solution of linear time-invariant scenes by the matrix exponential.

Forces whose shape has no exact form (smdcli.shapes: Signal.exact) are replaced by
their first-order hold on the output grid (a piecewise-linear table), which is then
integrated exactly; the error is that of the hold, O(step^2), and `auto` does
not choose this path (it integrates such forces to the scenario's tolerance).

The structure's state y = [x; v] is augmented with the exosystem state w of
every force (see forcing.py): z' = [[A, G], [0, S]] z. Between force
breakpoints z(t + h) = expm(Aaug h) z(t) is exact; at each breakpoint w is
reseeded from the signal's right limit, so jumps falling between output
points are honoured. On the uniform output grid, blocks of J steps are taken
at once with the stacked powers expm(Aaug j h), j = 1..J, which keeps the
Python loop short and the accumulated rounding small; w is reseeded at the
start of every block as well.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import time
from typing import NamedTuple

import numpy as np

from smdcli.model import Model
from smdcli.result import Result, SolverStats
from smdcli.solvers.exact.accurate_expm import flush_negligible
from smdcli.solvers.exact.arrow import ArrowFlow, arrow_cost, arrow_sampled_states
from smdcli.solvers.exact.dense_flow import PowersFlow, dense_cost
from smdcli.solvers.exact.hold import first_order_hold, halved, held_reason, hold_error, hold_response_error
from smdcli.solvers.base import Solver, Tolerances, make_result, segments, stated_rounding
from smdcli.solvers.exact import sampled
from smdcli.solvers.exact.harmonic import from_rest_less, split
from smdcli.solvers.exact.action import ACTION_DOFS, Action, action_cost, dense_action_cost, solve_action
from smdcli.solvers.exact.modal import modal_applies, solve_modal
from smdcli.text import plural

# propagate's reads of the same entries taken as one, up to this many bytes of output: beyond, the one larger
# product cost more than the calls it spared (OpenBLAS threads it: the 3-DOF forced scene's 12,001 steps took 8 ms
# merged, 0.6 ms read by read; below 2,000 steps the two are even)
_MERGED_BYTES = 2**17
# stacked x and v below which a sensitivity system's arrow never cost less than its dense exponential (10- to 63-mass
# chains: from 120 it did, or matched it), and the estimates are not worth their own time
ARROW_STATES = 100


def augmented(model: Model) -> tuple[np.ndarray, list[tuple[int, int, object]]]:
    """Aaug and, per signal, the slice of z that holds its exosystem state."""
    n2 = 2 * model.n
    exos = [s.exo() for s in model.signals]
    size = n2 + sum(e.S.shape[0] for e in exos)
    Aaug = np.zeros((size, size))
    Aaug[:n2, :n2] = model.state_matrix
    blocks = []
    col = n2
    for j, (signal, exo) in enumerate(zip(model.signals, exos)):
        m = exo.S.shape[0]
        Aaug[col:col + m, col:col + m] = exo.S
        Aaug[:n2, col:col + m] = np.outer(model.input_matrix[:, j], exo.g)
        blocks.append((col, col + m, signal))
        col += m
    return Aaug, blocks


def sparse_action(model: Model, grid: np.ndarray) -> Action | None:
    """The exponential's sparse action for a large linear scene whose forces all have exact generators, where it
    is cheaper than the dense exponential; else None."""
    if model.n < ACTION_DOFS or not model.is_linear or any(s.exo() is None for s in model.signals):
        return None
    action = Action(model)
    return action if action_cost(action, model, grid) < dense_cost(model, grid) else None


class Exact(Solver):
    """State transition by matrix exponential; forces integrated exactly between their breakpoints."""

    linear_only = True
    adaptive = False

    def refuse(self, model: Model) -> str | None:
        """A linear scene, or a piecewise-linear one (elastoplastic, bilinear, Coulomb friction, stops: solved event to
        event by smdcli.solvers.events.piecewise)."""
        if model.is_linear or model.is_piecewise_linear:
            return None
        smooth = [p for p in model.nonlinear_paths if p not in {e.path for e in model.nonsmooth}]
        curved = [f"{e.path} ({e.law_label})" for e in model.nonsmooth
                  if not e.law.piecewise_linear]
        first = (smooth or curved)[0]
        return (f"'exact' needs a linear model; {first} is nonlinear" + (" between events" if not smooth else "")
                + " (piecewise-linear scenes of elastoplastic and bilinear springs, Coulomb friction and stops are "
                "solved exactly too); try 'DOP853', 'Radau' or 'auto'")

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        import scipy.linalg  # before the clock: the wall time is the solve's own, not the import's
        import scipy.sparse

        del scipy

        start = time.perf_counter()
        original = model
        model, held = first_order_hold(model, grid)
        harmonics = split(model)
        if harmonics is not None:  # thousands of Fourier terms: superposed in closed form, not augmented
            reduced, particular = harmonics
            x, v, stated, message, _ = _solve_linear(from_rest_less(reduced, particular, float(grid[0])), grid)
            xp, vp = particular.at(grid)
            x, v, acceleration = x + xp, v + vp, None
            stated = stated + particular.accuracy(grid)
            message += f"; {plural(len(particular.w), 'harmonic')} superposed in closed form"
        else:
            x, v, stated, message, acceleration = _solve_linear(model, grid)
        reason = ""
        if held and harmonics is None and len(grid) > 1:
            fine = halved(grid)
            stated = max(stated, hold_response_error(x, lambda: _solve_linear(first_order_hold(original, fine)[0],
                                                                               fine).x))
        if held:
            stated = max(stated, hold_error(original, grid, held))
            message += f"; first-order hold on the output grid for {', '.join(held)} (error O(step^2))"
            reason = held_reason(original, stated)
        stats = SolverStats(
            method=self.name, requested_method=self.name, reason=reason,
            nlu=0, steps_accepted=max(len(grid) - 1, 0), wall_time_s=time.perf_counter() - start,
            message=message, stated_accuracy=stated,
        )
        return make_result(model, grid, x, v, stats, acceleration=acceleration)


class Solved(NamedTuple):
    """A path's displacement and velocity (N, n), its stated accuracy and description, and the acceleration where
    the path read it off its own state (the dense one: a product by the state matrix's rows, no force evaluated)."""

    x: np.ndarray
    v: np.ndarray
    stated: float
    message: str
    acceleration: np.ndarray | None = None


def _solve_linear(model: Model, grid: np.ndarray) -> Solved:
    """x, v, stated accuracy and a description, by the cheapest exact path (_path's). Each path steps a uniform
    grid; a grid of other steps (an internal caller's) is taken as its uniform runs one after the other."""
    path, how = _path(model, grid)
    if path == "runs":
        return _solve_runs(model, grid, how)
    if path == "modal":
        return Solved(*solve_modal(model, grid))
    if path == "action":
        return Solved(*solve_action(model, grid, how))
    return Solved(*sampled.solve_sampled(model, how, *augmented(model))) if path == "sampled" \
        else solve_dense(model, grid)


def _path(model: Model, grid: np.ndarray) -> tuple[str, object]:
    """Which exact path a scene takes on the grid, and what it takes it with: ("runs", the grid's uniform runs),
    ("modal", None), ("action", the sparse action), ("sampled", a table's knots: blocks of steps between its
    samples) or ("dense", None), the first that applies."""
    runs = _uniform_runs(grid)
    if len(runs) > 1:
        return "runs", runs
    if modal_applies(model):
        return "modal", None
    action = sparse_action(model, grid)
    if action is not None:
        return "action", action
    knots = sampled.uniform_knots(model, grid)
    return ("sampled", knots) if knots is not None else ("dense", None)


def read_exactly(model: Model, grid: np.ndarray, readouts: list, copies: int = 0) -> tuple[float, str] | None:
    """Each of readouts' (R (r, 2n), G (r, signals) or None, out (N, r)) given R [x; v] + G u at every grid time (u
    the force signals' values there), where Exact.solve steps the augmented system or a table's samples (every
    force with its generator, no harmonics superposed, _path dense or sampled): only what is read is written, each
    output contiguous. copies: where the model is a sensitivity system, the scene's copies it stacks (arrow.py: its
    flow by its arrow structure where that serves). The stated accuracy and a description; None where Exact.solve
    takes another path (the caller solves it as a Result)."""
    if first_order_hold(model, grid)[1] or split(model) is not None:
        return None
    arrow = _arrow_flow(model, grid, readouts, copies) if copies else None
    if arrow is not None:
        return propagate(model, grid, readouts, arrow)
    path, knots = _path(model, grid)
    if path == "dense":
        return propagate(model, grid, readouts)
    if path != "sampled":
        return None
    # a record's samples: the copies' recurrence by the arrow where two or more share it (one copy: even, measured)
    system = augmented(model)
    found = arrow_sampled_states(model, knots, *system, copies) if copies >= 2 and 2 * model.n >= ARROW_STATES \
        else None
    states, stated, message = found or sampled.sampled_states(model, knots, *system)
    for R, _, out in readouts:
        np.matmul(states, R.T, out=out)
    _add_forces(model, grid, readouts)
    return stated, message


def _add_forces(model: Model, grid: np.ndarray, readouts: list, evaluated: list[int] | None = None) -> None:
    """out += u G^T for the readouts that read the forces (u the signals' values on the grid; evaluated: the signals
    that are, where not all)."""
    inputs = [(G, out) for _, G, out in readouts if G is not None and G.any()]
    if evaluated is None:
        evaluated = list(range(len(model.signals)))
    evaluated = [j for j in evaluated if any(G[:, j].any() for G, _ in inputs)]
    if evaluated:
        values = np.empty((len(grid), len(evaluated)))
        for column, j in enumerate(evaluated):
            values[:, column] = model.signals[j].value(grid)
        for G, out in inputs:
            out += values @ G[:, evaluated].T


def _uniform_runs(grid: np.ndarray) -> list[tuple[int, int]]:
    """The grid's maximal runs of equal steps (to 1e-9 of the step), as (first, last) indices sharing their ends."""
    steps = np.diff(grid)
    if len(steps) < 2:
        return [(0, len(grid) - 1)]
    breaks = np.flatnonzero(np.abs(np.diff(steps)) > 1e-9 * np.maximum(steps[1:], steps[:-1])) + 1
    ends = [0, *breaks.tolist(), len(steps)]
    return [(lo, hi) for lo, hi in zip(ends[:-1], ends[1:])]


def _solve_runs(model: Model, grid: np.ndarray, runs) -> Solved:
    """The linear scene on each uniform run in turn, each from the state the last one ended in."""
    x, v = np.empty((len(grid), model.n)), np.empty((len(grid), model.n))
    stated, message, start = 0.0, "", model
    for lo, hi in runs:
        xs, vs, accuracy, described, _ = _solve_linear(start, grid[lo:hi + 1])
        message = message or described
        x[lo:hi + 1], v[lo:hi + 1] = xs, vs
        stated = max(stated, accuracy)
        start = dataclasses.replace(model, x0=xs[-1].copy(), v0=vs[-1].copy())
    return Solved(x, v, stated, f"{message}; a grid of unequal steps, as {len(runs)} uniform runs")


def _in_blocks(reads: list, k: int, stop: int, z: np.ndarray, flow, seeds) -> np.ndarray:
    """Rows k .. stop - 1 of each read's output from z at row k - 1 (in the flow's order), in blocks of flow.J steps
    (the step's propagator to the 1st .. Jth power: flow.step), the force generators restarted at each block's start
    (seeds(rows): their states at those rows, (len(rows), m), z's flow.generators): the starts one after another,
    then every whole block's steps in one matrix product per read (not a product of the stacked powers with each
    start: twice the speed at size 27, where that is flops, not Python). reads: (R P, columns, out), the read's rows
    times the powers (J, r, columns) on the state's columns that reach it, and its (N, r) output. The state at
    stop - 1."""
    J, size = flow.J, len(z)
    count = stop - k
    whole, rest = divmod(count, J)
    starts = np.empty((whole + (rest > 0), size))
    restarts = seeds(k - 1 + J * np.arange(len(starts)))
    for b in range(len(starts)):
        z[flow.generators] = restarts[b]
        starts[b] = z
        z = flow.step(z, min(J, count - b * J))
    flush_negligible(starts)  # a far mass still at rest, 1e-250 m, met by a far power's 1e-100: a subnormal product
    for read, columns, out in reads:
        r, known = out.shape[1], _on_columns(starts, columns, axis=1)
        if whole:
            np.matmul(known[:whole], read.reshape(J * r, len(columns)).T,
                      out=out[k:k + whole * J].reshape(whole, J * r))
        if rest:
            out[k + whole * J:stop] = (read[:rest].reshape(rest * r, len(columns)) @ known[whole]).reshape(rest, r)
    return z


def _arrow_flow(model: Model, grid: np.ndarray, readouts: list, copies: int) -> ArrowFlow | None:
    """The sensitivity system's flow by its arrow structure (arrow.py), where it serves and costs less than the
    dense or sparse path _path would take (estimated, the sparse action's without building it): a uniform grid with
    no record's samples between its points, and every readout reading the scene and at most one copy."""
    N, n = len(grid), model.n // (copies + 1)
    if 2 * model.n < ARROW_STATES or N < 2 or len(_uniform_runs(grid)) > 1 or modal_applies(model) \
            or any(s.exo() is None for s in model.signals) or sampled.uniform_knots(model, grid) is not None:
        return None
    for R, _, _ in readouts:
        reached = np.abs(R).reshape(len(R), 2, copies + 1, n).sum(axis=(0, 1, 3))[1:]  # each copy's x and v
        if np.count_nonzero(reached) > 1:
            return None
    Aaug = augmented(model)[0]
    rows = sum(len(R) for R, _, _ in readouts)
    cost = arrow_cost(len(Aaug) - 2 * copies * n, 2 * n, copies, N, rows)
    if cost >= dense_cost(model, grid) or (model.n >= ACTION_DOFS and
                                           dense_action_cost(Aaug, model.n, model, grid) < cost):
        return None
    return ArrowFlow.of(Aaug, n, copies, (grid[-1] - grid[0]) / (N - 1), N, rows)


def _on_columns(array: np.ndarray, columns: np.ndarray, axis: int) -> np.ndarray:
    """array's entries at columns along axis: a slice where they run unbroken (a scene's read reaches every entry of
    the state, and numpy's gather along the last axis is slow: a 30-mass chain's dense run 2.34 ms with it, 2.14
    without, minima of 80), else a gather."""
    if len(columns) and columns[-1] - columns[0] == len(columns) - 1:
        return array[(slice(None),) * axis + (slice(int(columns[0]), int(columns[-1]) + 1),)]
    return array.take(columns, axis=axis)


def _reads(readouts: list, flow, n: int, N: int, signal_rows: np.ndarray) -> tuple[list, list]:
    """propagate's reads: (rows R, R times the powers on the state's entries that reach them (J, r, columns), those
    columns, the (N, r) output), the readouts that reach the same entries taken as one read where their outputs
    together are small (a small scene's cost is its numpy calls: a 1-DOF sensitivity's six readouts are two reads);
    and each such read's (combined output, the readouts' outputs) to copy out after. signal_rows (signals, size):
    the forces read off their generators' states, g w (zero rows: the forces evaluated after)."""
    sizes = [len(R) for R, _, _ in readouts]
    starts = np.cumsum([0, *sizes[:-1]]).astype(int)
    size = signal_rows.shape[1]
    # every read's rows times the powers at once, then each read on the state's entries that reach it (a
    # sensitivity block: its own, the scene's, the forces')
    rows = np.zeros((sum(sizes), size))
    rows[:, :2 * n] = np.vstack([R for R, _, _ in readouts])
    for (_, G, _), first, count in zip(readouts, starts, sizes):
        if G is not None:
            rows[first:first + count] += G @ signal_rows
    if flow.order is not None:
        rows = rows[:, flow.order]
    read_all = flow.tables(flush_negligible(rows))  # (J, reads' rows, size), in the flow's order
    reaching = np.logical_or.reduceat(read_all.any(axis=0), starts, axis=0)  # (readouts, size)
    groups, filling = [], {}  # filling: the group being filled for each set of entries, and its rows so far
    for i, mask in enumerate(reaching):
        group, filled = filling.get(key := mask.tobytes(), (None, 0))
        if group is None or N * (filled + sizes[i]) * 8 > _MERGED_BYTES:
            group, filled = [], 0
            groups.append(group)
        group.append(i)
        filling[key] = group, filled + sizes[i]
    reads, merged = [], []
    for group in groups:
        picked = np.concatenate([np.arange(starts[i], starts[i] + sizes[i]) for i in group])
        columns = np.flatnonzero(reaching[group[0]])
        lo, hi = int(picked[0]), int(picked[-1]) + 1  # consecutive readouts (a block's x, v, a): a slice, not a copy
        read = read_all[:, lo:hi] if hi - lo == len(picked) else read_all[:, picked]
        read = np.ascontiguousarray(_on_columns(read, columns, axis=2))  # once: each segment's blocks reshape it
        out = readouts[group[0]][2] if len(group) == 1 else np.empty((N, len(picked)))
        if len(group) > 1:
            merged.append((out, [readouts[i][2] for i in group]))
        reads.append((rows[picked], read, columns, out))
    return reads, merged


def solve_dense(model: Model, grid: np.ndarray) -> Solved:
    """Displacement, velocity and acceleration (N, n) by the dense exponential of the augmented system (the
    acceleration read off the state, plus the forces' values at each time: a jump's sample its right limit), the
    stated accuracy and a description."""
    n, N = model.n, len(grid)
    x, v, a = (np.empty((N, n)) for _ in range(3))
    stated, message = propagate(model, grid, [(np.eye(n, 2 * n), None, x), (np.eye(n, 2 * n, n), None, v),
                                              (model.state_matrix[n:], model.input_matrix[n:], a)])
    return Solved(x, v, stated, message, a)


def propagate(model: Model, grid: np.ndarray, readouts, arrow: ArrowFlow | None = None) -> tuple[float, str]:
    """The dense exponential of the augmented system (state z = [x; v; the forces' generators]) stepped over the
    grid, each of readouts' (R (r, 2n), G (r, signals) or None, out (N, r)) given R [x; v] + G u at every grid
    time (read_exactly's); arrow: a sensitivity system's flow by its arrow structure (arrow.py), in place of the
    stacked system's exponential. The stated accuracy and a description."""
    Aaug, blocks = augmented(model)
    size = Aaug.shape[0]
    n, N = model.n, len(grid)
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    generators = slice(2 * n, size)
    flow = arrow if arrow is not None else PowersFlow(Aaug, h, N, sum(len(R) for R, _, _ in readouts), generators)

    def advance(z: np.ndarray, dt: float) -> np.ndarray:
        if N > 1 and abs(dt - h) <= 1e-9 * h:
            return flow.step(z, 1)  # a grid difference that is h up to the rounding of the grid times
        return flow.advance(z, dt)

    # a force smooth over the run (no breakpoint: a sine, a frequency's derivative) read off its generator's state
    # with the structure's, g w, not evaluated at every time (a third of a frequency's sensitivity on one DOF); one
    # with breakpoints is evaluated, a sample on a jump its right limit as the signal gives it
    smooth = [not len(signal.breakpoints(float(grid[0]), float(grid[-1]))) for _, _, signal in blocks]
    signal_rows = np.zeros((len(blocks), size))
    for j, (first, last, signal) in enumerate(blocks):
        if smooth[j]:
            signal_rows[j, first:last] = signal.exo().g
    reads, merged = _reads(readouts, flow, n, N, signal_rows)  # in the flow's order

    segs = segments(model, grid)
    # the generators' states at every segment's start at once (a record's thousands of segments)
    seeds = sampled.table_states(blocks, np.array([ta for ta, _ in segs], dtype=float), 2 * n)
    z = np.zeros(size)
    z[:n], z[n:2 * n] = model.x0, model.v0
    if flow.order is not None:
        z = z[flow.order]
    k = 0  # next grid index to fill
    n_expm = 1
    for seg_index, (ta, tb) in enumerate(segs):
        last = seg_index == len(segs) - 1
        z[flow.generators] = seeds[seg_index]
        t_cur = ta
        stop = N if last else int(np.searchsorted(grid, tb, side="left"))
        if k < stop:
            if grid[k] > t_cur:
                z = advance(z, grid[k] - t_cur)
                n_expm += 1
            for R, _, _, out in reads:
                out[k] = R @ z
            t_cur = grid[k]
            k += 1
            if k < stop:
                z = _in_blocks([r[1:] for r in reads], k, stop, z, flow,
                               lambda rows: sampled.table_states(blocks, grid[rows], 2 * n))
                k = stop
                t_cur = grid[k - 1]
        if not last and tb > t_cur:
            z = advance(z, tb - t_cur)
            n_expm += 1
    for combined, outs in merged:
        first = 0
        for out in outs:
            out[:] = combined[:, first:first + out.shape[1]]
            first += out.shape[1]
    _add_forces(model, grid, readouts, [j for j, read in enumerate(smooth) if not read])
    accurate = arrow is None and flow.accurate
    stated = stated_rounding(N + len(segs) + n_expm, 1.0 if accurate else flow.growth)
    if arrow is not None:
        how = f"its arrow's exponential (the scene's of size {arrow.q} and {plural(arrow.copies, 'copy', 'copies')})"
    else:
        how = (f"{plural(flow.exponentials, 'matrix exponential')} of size {size}"
               + (" in double-double (a stiff scene)" if accurate else ""))
    return stated, f"ok: {plural(len(segs), 'force segment')}, {how}"
