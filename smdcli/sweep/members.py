"""Time-domain families: every member solved (batched where linear, else in the pool) and measured
(peak, RMS, settling time, force to ground).

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from smdcli.errors import UsageError
from smdcli.model import build, time_grid
from smdcli.scenario import Scenario
from smdcli.sweep.batched import batched_exact, shared_signal_recurrence
from smdcli.sweep.family import Family
from smdcli.sweep.pool import default_workers, run_pool, run_threads
from smdcli.sweep.spec import EXACT_METHODS, MAX_STACKED, QUANTITIES, SETTLING_BAND, _trapezoid

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

    @property
    def acceleration(self) -> np.ndarray:
        """(S, N, n) acceleration, derived on first use where the batched path deferred it."""
        if callable(self.derived_acceleration):
            self.derived_acceleration = self.derived_acceleration()
        return self.derived_acceleration


def _histories(result) -> tuple:
    """A member's time and its histories in QUANTITIES order."""
    return result.time, (result.displacement, result.velocity, result.acceleration, result.force)


def _status(result) -> tuple:
    """A member's success, message (with the failure time), method and stated accuracy."""
    message = "ok" if result.success else f"{result.stats.message} (t = {result.t_failed:g} s)"
    return result.success, message, result.stats.method, result.stats.stated_accuracy


def _solve_member(args: tuple[Scenario, str | None]) -> tuple:
    """Worker: solve one member with its own solver settings (or the override): (histories, status)."""
    from smdcli.solvers.checked import solve_scenario

    sc, method = args
    result = solve_scenario(sc, build(sc), time_grid(sc.time), method)
    return _histories(result), _status(result)


def _solve_model(args: tuple[Family, int, np.ndarray, str | None, dict[str, np.ndarray]]) -> tuple:
    """Thread task: solve member s of a family that holds matrices and coefficients, not scenarios, writing its
    histories straight into row s of the family's stacks; returns its status."""
    from smdcli.solvers.checked import solve_scenario

    family, s, grid, method, stacks = args
    result = solve_scenario(family.scenario, family.model(s), grid, method)
    for name, data in zip(QUANTITIES, _histories(result)[1]):
        stacks[name][s] = data
    return _status(result)


def solve_family(family: Family, method: str | None = None, workers: int | None = None,
                 progress: Callable[[int], None] | None = None) -> FamilyResult:
    """Every member's time response: one batched exact recurrence when linear, else a process pool."""
    start = time.perf_counter()
    S, n = len(family), family.base.n
    scenarios = family.scenarios
    grids = [time_grid(sc.time) for sc in scenarios] if scenarios else [time_grid(family.scenario.time)]
    grid = grids[0]
    same_grid = all(len(g) == len(grid) and np.array_equal(g, grid) for g in grids)
    longest = max(len(g) for g in grids)
    if S * longest * n > MAX_STACKED:
        raise UsageError(f"{S} members x {longest} time points x {n} DOFs is more than {MAX_STACKED:.0e} samples "
                         "per data set; use fewer members or a coarser time grid")
    requested = {method} if method else {sc.solver.method for sc in (scenarios or [family.scenario])}
    exact_ok = requested <= set(EXACT_METHODS) and family.base.is_linear and same_grid
    batched = None
    if exact_ok and scenarios is None and all(s.exo() is not None for s in family.base.signals):
        x, v, acc = shared_signal_recurrence(family, grid)
        force = family.base.applied_force(grid) if family.base.is_forced else np.zeros((len(grid), n))
        batched = np.broadcast_to(force, (S,) + force.shape)
        how = f"one batched exact recurrence over {S} members"
    elif exact_ok:
        models = [family.model(s) for s in range(S)]
        batched = batched_exact(models, grid)
        how = f"one batched exact recurrence over {S} members (each with its own forces)"
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
        stacks = {name: np.empty(shape) for name in QUANTITIES}  # every row is written whole by its member
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
    success, messages, methods, stated = zip(*statuses)
    pool = "threads" if threaded else "process pool"
    how = f"{pool} of {min(workers, S)} workers" if workers > 1 and S > 1 else "one process"
    return FamilyResult(grid if same_grid else times, family.base.dofs, stacks["displacement"],
                        stacks["velocity"], stacks["acceleration"], stacks["force"],
                        np.array(success), list(messages), list(methods), how, time.perf_counter() - start,
                        np.array(stated))


def _batched_stated(family: Family, grid: np.ndarray) -> np.ndarray:
    """Rounding the batched exact recurrence vouches for, per member: 8 u N max(1, ||A h||_1) (see stated_rounding)."""
    from smdcli.solvers.base import stated_rounding

    h = float(grid[1] - grid[0]) if len(grid) > 1 else 0.0
    stiffness = np.abs(np.linalg.solve(family.M, family.K)).sum(axis=1).max(axis=-1)
    damping = 1 + np.abs(np.linalg.solve(family.M, family.C)).sum(axis=1).max(axis=-1)
    norm = np.maximum(stiffness, damping) * h
    return np.array([stated_rounding(len(grid), g) for g in norm])


def ground_force(family: Family, result: FamilyResult) -> np.ndarray:
    """Force each DOF passes to the ground through the elements tied to it, (S, N, n): with K's and C's
    row sums as the ground stiffness and damping (internal elements cancel in a row sum)."""
    x, v = result.displacement, result.velocity
    force = x * family.K.sum(axis=2)[:, None, :] + v * family.C.sum(axis=2)[:, None, :]
    if family.base.is_linear:
        return force
    for s in range(len(family)):
        model = family.model(s)
        for incidence, on_velocity in ((model.cubic, False), (model.quadratic, True)):
            for row, coef in zip(incidence.D, incidence.coef) if incidence is not None else ():
                if np.count_nonzero(row) == 1:
                    j = int(np.flatnonzero(row)[0])
                    d = row[j] * (v[s] if on_velocity else x[s])[:, j]
                    force[s, :, j] += row[j] * coef * (np.abs(d) * d if on_velocity else d**3)
    return force


def metrics(family: Family, result: FamilyResult) -> dict[str, np.ndarray]:
    """Scalar measures of each member per DOF, (S, n) each: peak and RMS displacement, 2 % settling
    time (NaN where the response has not settled by the end) and peak force passed to the ground."""
    x = result.displacement
    S, N, n = x.shape
    t = result.time if result.time.ndim == 2 else np.broadcast_to(result.time, (S, N))
    valid = np.isfinite(t)
    count = valid.sum(axis=1)
    with np.errstate(all="ignore"):
        peak = np.nanmax(np.abs(x), axis=1)
        span = np.nanmax(t, axis=1) - t[:, 0]
        rms = np.sqrt(_trapezoid(np.nan_to_num(x) ** 2, np.nan_to_num(t)[..., None], axis=1) / span[:, None]) \
            if N > 1 else np.abs(x[:, 0])
        final = x[np.arange(S), count - 1]  # (S, n)
        deviation = np.abs(x - final[:, None, :])
        band = SETTLING_BAND * np.nanmax(deviation, axis=1)
        outside = deviation > band[:, None, :]
        last_out = np.where(outside.any(axis=1), N - 1 - np.argmax(outside[:, ::-1, :], axis=1), -1)
        after = np.minimum(last_out + 1, N - 1)
        settling = np.where(last_out < 0, t[:, :1], np.take_along_axis(t, after, axis=1))
        settling = np.where(last_out >= (count[:, None] - 1) - max(1, int(SETTLING_BAND * N)), np.nan, settling)
        ground = np.nanmax(np.abs(ground_force(family, result)), axis=1)
    return {"peak_displacement": peak, "rms_displacement": rms, "settling_time": settling,
            "peak_ground_force": ground}
