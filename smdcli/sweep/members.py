"""Time-domain families: every member solved (batched where linear, else in the pool) and measured
(peak, RMS, settling time, force to ground).

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from smdcli.errors import UsageError
from smdcli.model import build, mass_solve, time_grid
from smdcli.scenario import Scenario
from smdcli.solvers.peaks import jump_times, located_drifts, result_peaks, row_peaks
from smdcli.solvers.registry import EXACT_NAMES
from smdcli.sweep.batched import batched_exact, shared_signal_recurrence
from smdcli.sweep.family import Family
from smdcli.sweep.pool import default_workers, run_pool, run_threads
from smdcli.sweep.spec import MAX_STACKED, METRICS, QUANTITIES, SETTLING_BAND, STOREY_METRICS

# --------------------------------------------------------------- families


@dataclass
class FamilyResult:
    """Stacked results of a time-domain family: (S, N, n) arrays and per-member status."""

    time: np.ndarray  # (N,), or (S, N) padded with NaN when members have different grids
    dofs: tuple[str, ...]
    displacement: np.ndarray
    velocity: np.ndarray
    derived_acceleration: np.ndarray | Callable[[], np.ndarray]  # the array, or how to make it on demand
    force: np.ndarray
    success: np.ndarray  # (S,) bool
    messages: list[str]
    methods: list[str]
    how: str
    wall_time_s: float
    stated_accuracy: np.ndarray | None = None  # (S,) each member's vouched error relative to its peaks
    located_peak: np.ndarray | None = None  # (S, n) each member's peak |x| located by its own run (events too)
    located_drift: np.ndarray | None = None  # (S, n) and its storey's peak drift at each chain mass (NaN elsewhere)

    @property
    def acceleration(self) -> np.ndarray:
        """(S, N, n) acceleration, derived on first use where the batched path deferred it."""
        if callable(self.derived_acceleration):
            self.derived_acceleration = self.derived_acceleration()
        return self.derived_acceleration


def _histories(result) -> tuple:
    """A member's time and its histories in QUANTITIES order."""
    return result.time, (result.displacement, result.velocity, result.acceleration, result.force)


def _status(result, sc: Scenario, model) -> tuple:
    """A member's success, message (with the failure time), method, stated accuracy, peak |x| per DOF located
    between samples and at its events (solvers.peaks.result_peaks: a stop's contact point, a yield's corner), and
    of a scene with [building] each chain mass's storey drift peak located as well (NaN elsewhere)."""
    message = "ok" if result.success else f"{result.stats.message} (t = {result.t_failed:g} s)"
    drift = np.full(len(result.dofs), np.nan)
    if sc.building is not None and result.success and len(result.time) > 1:
        chain = [result.dofs.index(name) for name in sc.building.masses]
        drift[chain] = located_drifts(result, model, chain)[0]
    return result.success, message, result.stats.method, result.stats.stated_accuracy, result_peaks(result), drift


def _solve_member(args: tuple[Scenario, str | None]) -> tuple:
    """Worker: solve one member with its own solver settings (or the override): (histories, status)."""
    from smdcli.solvers.run import solve_scenario

    sc, method = args
    model = build(sc)
    result = solve_scenario(sc, model, time_grid(sc.time), method)
    return _histories(result), _status(result, sc, model)


def _solve_model(args: tuple[Family, int, np.ndarray, str | None, dict[str, np.ndarray]]) -> tuple:
    """Thread task: solve member s of a family that holds matrices and coefficients, not scenarios, writing its
    histories straight into row s of the family's stacks; returns its status."""
    from smdcli.solvers.run import solve_scenario

    family, s, grid, method, stacks = args
    model = family.model(s)
    result = solve_scenario(family.scenario, model, grid, method)
    for name, data in zip(QUANTITIES, _histories(result)[1]):
        stacks[name][s] = data
    return _status(result, family.scenario, model)


# The most DOFs whose members one batched exact recurrence steps together: its step is a Python loop over the (2n)^2
# entries of the members' transition matrices, each a vector over them. Measured on chains of 100 members (2 s on
# 201 points): 0.02 s against 0.32 s solved one by one at 5 masses, even at 20 (0.30 s and 0.31 s), slower at 50
# (2.0 s against 1.8 s); at 2,500 masses it did not finish in 10 minutes.
BATCHED_DOFS = 32


def solve_family(family: Family, method: str | None = None, workers: int | None = None,
                 progress: Callable[[int], None] | None = None,
                 buffers: dict[str, np.ndarray] | None = None) -> FamilyResult:
    """Every member's time response: one batched exact recurrence when linear, else threads or a process pool.
    buffers: arrays (at least S, N, n) per quantity that members solved on threads write into, reused from chunk
    to chunk (fresh memory is slow to touch: 0.4 s per 160 MB measured)."""
    start = time.perf_counter()
    S, n = len(family), family.base.n
    scenarios = family.scenarios
    grid, longest = family.output_grid()
    same_grid = grid is not None
    if S * longest * n > MAX_STACKED:
        raise UsageError(f"{S} members x {longest} time points x {n} DOFs is more than {MAX_STACKED:.0e} samples "
                         "per data set; use fewer members or a coarser time grid")
    requested = {method} if method else {sc.solver.method for sc in (scenarios or [family.scenario])}
    # Ground jumps restart each member's run (solved one by one); the ground's effective force -M 1 a_g is shared
    # only by members of one mass matrix.
    exact_ok = requested <= set(EXACT_NAMES) and family.base.is_linear and same_grid and not family.base.jumps \
        and n <= BATCHED_DOFS
    shared_force = family.base.ground is None or bool(np.all(family.M == family.M[:1]))
    batched = None
    if exact_ok and scenarios is None and shared_force and all(s.exo() is not None for s in family.base.signals):
        x, v, acc = shared_signal_recurrence(family, grid)
        force = family.base.applied_force(grid) if family.base.is_forced else np.zeros((len(grid), n))
        batched = np.broadcast_to(force, (S,) + force.shape)
        how = "one batched exact recurrence"
    elif exact_ok:
        models = [family.model(s) for s in range(S)]
        batched = batched_exact(models, grid)
        how = "one batched exact recurrence (each member with its own forces)"
        if batched is not None:
            x, v = batched
            batched = np.stack([m.applied_force(grid) if m.is_forced else np.zeros((len(grid), n)) for m in models])
            with np.errstate(all="ignore"):
                acc = np.stack([m.acceleration(x[s], v[s], batched[s]) for s, m in enumerate(models)])
    if batched is not None:
        force = batched
        if progress:
            progress(S)
        finite = np.isfinite(x).all(axis=(1, 2)) & np.isfinite(v).all(axis=(1, 2))
        messages = ["ok" if ok else "the solution is not finite (NaN or inf): the member's numbers overflow "
                    "double precision" for ok in finite]
        return FamilyResult(grid, family.base.dofs, x, v, acc, force, finite, messages,
                            ["exact"] * S, how, time.perf_counter() - start, _batched_stated(family, grid))
    workers = workers or default_workers()
    threaded = scenarios is None and same_grid
    shape = (S, longest, n)
    times = np.full((S, longest), np.nan)
    if threaded:  # members are one model with other numbers: solved in this process, on threads, into the stacks
        fits = buffers is not None and all(buffers[q].shape[0] >= S and buffers[q].shape[1:] == shape[1:]
                                           for q in QUANTITIES)
        # every row is written whole by its member
        stacks = {q: buffers[q][:S] if fits else np.empty(shape) for q in QUANTITIES}
        tasks = [(family, s, grid, method, stacks) for s in range(S)]
        statuses = run_threads(_solve_model, tasks, workers, progress)
        times[:] = grid
    else:
        tasks = [(family.member_scenario(s), method) for s in range(S)]
        outcomes = run_pool(_solve_member, tasks, workers, progress)
        stacks = {name: np.full(shape, np.nan) for name in QUANTITIES}
        for s, ((t, histories), _) in enumerate(outcomes):
            times[s, :len(t)] = t
            for name, data in zip(QUANTITIES, histories):
                stacks[name][s, :len(t)] = data
        statuses = [status for _, status in outcomes]
    success, messages, methods, stated, peaks, drift = zip(*statuses)
    pool = "threads" if threaded else "process pool"
    how = f"{pool} of {min(workers, S)} workers" if workers > 1 and S > 1 else "one process"
    return FamilyResult(grid if same_grid else times, family.base.dofs, stacks["displacement"],
                        stacks["velocity"], stacks["acceleration"], stacks["force"],
                        np.array(success), list(messages), list(methods), how, time.perf_counter() - start,
                        np.array(stated), located_peak=np.array(peaks, dtype=float).reshape(S, n),
                        located_drift=np.array(drift, dtype=float).reshape(S, n))


def _batched_stated(family: Family, grid: np.ndarray) -> np.ndarray:
    """Rounding the batched exact recurrence vouches for, per member: 8 u N max(1, ||A h||_1) (see stated_rounding)."""
    from smdcli.solvers.base import stated_rounding

    h = float(grid[1] - grid[0]) if len(grid) > 1 else 0.0
    stiffness = np.abs(mass_solve(family.M, family.K)).sum(axis=1).max(axis=-1)
    damping = 1 + np.abs(mass_solve(family.M, family.C)).sum(axis=1).max(axis=-1)
    norm = np.maximum(stiffness, damping) * h
    return np.array([stated_rounding(len(grid), g) for g in norm])


METRIC_SAMPLES = 1 << 18  # samples (members x time points x DOFs) measured at a time: 2 MB temporaries, reused


def _ground_elements(family: Family) -> list[tuple[bool, int, float, np.ndarray]]:
    """Nonlinear elements tied to the ground: (on velocity, DOF, sign in D, (S,) coefficients)."""
    tied = []
    for name, on_velocity in (("cubic", False), ("quadratic", True)):
        incidence = getattr(family.base, name)
        if incidence is None:
            continue
        stacked = getattr(family, f"{name}_coef")
        if stacked is None:
            stacked = np.stack([getattr(family.model(s), name).coef for s in range(len(family))]) \
                if family.scenarios is not None else np.broadcast_to(incidence.coef, (len(family), len(incidence)))
        for e, row in enumerate(incidence.D):
            if np.count_nonzero(row) == 1:
                j = int(np.flatnonzero(row)[0])
                tied.append((on_velocity, j, float(row[j]), stacked[:, e]))
    return tied


def _ground_force(family: Family, x: np.ndarray, v: np.ndarray, members: slice, tied: list) -> np.ndarray:
    """Force each DOF passes to the ground through the elements tied to it, (s, n, N) like x and v (members' DOFs
    by time): with K's and C's row sums as the ground stiffness and damping (internal elements cancel in a row sum)."""
    force = x * family.K[members].sum(axis=2)[:, :, None]
    force += v * family.C[members].sum(axis=2)[:, :, None]
    for on_velocity, j, sign, coef in tied:
        d = sign * (v if on_velocity else x)[:, j, :]
        force[:, j, :] += sign * coef[members][:, None] * (np.abs(d) * d if on_velocity else d**3)
    return force


def metrics(family: Family, result: FamilyResult, errors: dict | None = None) -> dict[str, np.ndarray]:
    """Scalar measures of each member per DOF, (S, n) each: peak and RMS displacement, 2 % settling
    time (NaN where the response has not settled by the end) and peak force passed to the ground. Into `errors`,
    if given: settling_time, how far (s) each may be off because of the members' errors of x."""
    S, N, n = result.displacement.shape
    tied = _ground_elements(family)
    # peaks located between samples where the motion is smooth between them but at the base's jumps; members solved
    # one by one bring their own (result.located_peak), at their events too
    locate = not family.base.nonsmooth and result.time.ndim == 1 and N > 2 and result.located_peak is None
    jumps = jump_times(family.base, result.time) if locate else np.empty(0)
    measured = {name: np.empty((S, n)) for name in METRICS + ("settling_time_error",)}
    block = max(1, METRIC_SAMPLES // (N * n))
    for start in range(0, S, block):
        members = slice(start, min(start + block, S))
        t = result.time[members] if result.time.ndim == 2 else result.time
        # DOFs by time: every reduction below runs along contiguous memory (20x faster than along the middle axis)
        x, v = (np.ascontiguousarray(q[members].transpose(0, 2, 1)) for q in (result.displacement, result.velocity))
        with np.errstate(all="ignore"):
            error = np.nan_to_num(result.stated_accuracy[members], nan=np.inf) * _peak(_peak(x))
        for name, values in measures(t, x, _ground_force(family, x, v, members, tied), N, error).items():
            measured[name][members] = values
        if locate:
            measured["peak_displacement"][members] = np.fmax(
                measured["peak_displacement"][members], _located(t, result, members, jumps))
        if result.located_peak is not None:  # members solved one by one located their own, at their events too
            measured["peak_displacement"][members] = np.fmax(measured["peak_displacement"][members],
                                                             result.located_peak[members])
    settling_error = measured.pop("settling_time_error")
    if errors is not None:
        errors["settling_time"] = settling_error
    building = family.scenario.building
    if building is None:
        for name in STOREY_METRICS:
            measured.pop(name)
    else:
        measured.update(_storey_metrics(family, result, building, jumps if locate else None))
    return measured


def _storey_metrics(family: Family, result: FamilyResult, building, events) -> dict[str, np.ndarray]:
    """peak_drift_ratio and residual_drift (S, n): at each chain mass, its storey's (the mass less the one below,
    the ground's 0; the peak located between samples where the others are, over the storey's height); NaN at a mass
    not in the chain."""
    S, N, n = result.displacement.shape
    index = {name: i for i, name in enumerate(family.base.dofs)}
    chain = [index[name] for name in building.masses]
    below = [None] + chain[:-1]
    out = {name: np.full((S, n), np.nan) for name in STOREY_METRICS}
    count = np.isfinite(result.time).sum(axis=-1) if result.time.ndim == 2 else np.full(S, N)
    for j, lower, height in zip(chain, below, building.storey_heights):
        drift = [q[:, :, j] - (q[:, :, lower] if lower is not None else 0.0)
                 for q in (result.displacement, result.velocity, result.acceleration)]
        with np.errstate(all="ignore"):
            peak = _peak(drift[0])
        if events is not None:
            peak = np.fmax(peak, row_peaks(result.time, *drift, events=events))
        if result.located_drift is not None:  # members solved one by one located their own, at their events too
            peak = np.fmax(peak, result.located_drift[:, j])
        out["peak_drift_ratio"][:, j] = peak / height
        out["residual_drift"][:, j] = drift[0][np.arange(S), count - 1]
    return out


def _located(t: np.ndarray, result: FamilyResult, members: slice, jumps: np.ndarray) -> np.ndarray:
    """Each member's peak |x| per DOF (s, n), located between samples on the quintic Hermite (solvers.peaks)."""
    x, v, a = (q[members] for q in (result.displacement, result.velocity, result.acceleration))
    s, N, n = x.shape
    rows = lambda q: q.transpose(0, 2, 1).reshape(s * n, N)  # noqa: E731 (member and DOF by time)
    return row_peaks(t, rows(x), rows(v), rows(a), events=jumps).reshape(s, n)


def measures(t: np.ndarray, x: np.ndarray, ground: np.ndarray, N: int,
             error: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The metrics of a few members: t (N,) shared or (s, N) padded with NaN, x and ground (s, n, N); with each
    member's error of x (s,), also settling_time_error, how far (s) the settling time may be off because of it."""
    S = len(x)
    t = np.broadcast_to(t, (S, N))
    count = np.isfinite(t).sum(axis=1)
    with np.errstate(all="ignore"):
        peak = _peak(x)
        span = np.nanmax(t, axis=1) - t[:, 0]
        if N > 1:  # trapezoid rule as weights on the samples: RMS^2 = sum_k w_k x_k^2 / span
            dt = np.nan_to_num(np.diff(t, axis=1))
            weights = np.zeros((S, 1, N))
            weights[:, 0, 1:] += dt / 2
            weights[:, 0, :-1] += dt / 2
            # numpy's own sum, not a BLAS product: its order does not depend on how many threads BLAS has (a Dask
            # worker has one), so a member's RMS is the same bits wherever it is measured
            squares = np.nan_to_num(np.square(x), copy=False)
            squares *= weights
            rms = np.sqrt(squares.sum(axis=2) / span[:, None])
        else:
            rms = np.abs(x[:, :, 0])
        final = x[np.arange(S), :, count - 1]  # (S, n)
        deviation = np.abs(np.subtract(x, final[:, :, None]))
        band = SETTLING_BAND * np.fmax.reduce(deviation, axis=2)

        def settled(outside: np.ndarray) -> np.ndarray:  # the sample after the last one outside the band
            last_out = np.where(outside.any(axis=2), N - 1 - np.argmax(outside[:, :, ::-1], axis=2), -1)
            after = np.minimum(last_out + 1, N - 1)
            at = np.where(last_out < 0, t[:, :1], np.take_along_axis(t, after, axis=1))
            return np.where(last_out >= (count[:, None] - 1) - max(1, int(SETTLING_BAND * N)), np.nan, at)

        settling = settled(deviation > band[:, :, None])
        ground = _peak(ground)
        found = {"peak_displacement": peak, "rms_displacement": rms, "settling_time": settling,
                 "peak_ground_force": ground}
        if error is not None:
            # A sample within x's error of the band's edge may lie on either side of it: the settling time is then
            # anywhere between the times those choices give (a step of the grid, or a whole lobe away)
            slack = 2 * (1 + SETTLING_BAND) * np.asarray(error, dtype=float)[:, None, None]
            early = settled(deviation > band[:, :, None] + slack)
            late = settled(deviation > band[:, :, None] - slack)
            flips = np.isnan(early) != np.isnan(late)
            spread = np.fmax(np.abs(late - settling), np.abs(settling - early))
            found["settling_time_error"] = np.where(flips, np.inf, np.nan_to_num(spread))
    return found


def _peak(q: np.ndarray) -> np.ndarray:
    """Largest |q| over time (the last axis), NaN ignored (NaN where all are), without a temporary of q's size."""
    return np.fmax(np.fmax.reduce(q, axis=-1), -np.fmin.reduce(q, axis=-1))
