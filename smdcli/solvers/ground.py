"""Runs with support motion: restarts where the ground's displacement or velocity jumps, and the ground's own
history (its displacement and velocity integrated exactly where only its acceleration is given).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from smdcli.model import Model
from smdcli.result import GroundHistory, Result
from smdcli.solvers.base import Tolerances, make_result

# The ground's integrated displacement and velocity, where its acceleration has no exact generator (a sweep,
# an expression): compiled DOP853 at this relative tolerance.
GROUND_RTOL = 1e-12


def jump_at(model: Model, t: float) -> np.ndarray:
    """The ground's jump of the relative state at t, [dx; dv] (2n,), the model's jumps there summed; LookupError where
    it has none there (a pulse a parameter moves in time)."""
    found = [np.concatenate([dx, dv]) for when, dx, dv in model.jumps if abs(when - t) <= 1e-12 * max(abs(t), 1.0)]
    if not found:
        raise LookupError(t)
    return np.sum(found, axis=0)


def across_jumps(solve: Callable[[Model, np.ndarray], Result], model: Model, grid: np.ndarray) -> Result:
    """solve(model, grid), restarted at each jump of the state: between jumps the solver runs on the output points
    there (a uniform grid), joined to the jumps by one step each; the output at a jump's time is its right limit."""
    if not model.jumps:
        return solve(model, grid)
    N = len(grid)
    x = np.full((N, model.n), np.nan)
    v = np.full((N, model.n), np.nan)
    bounds = [float(grid[0])] + [t for t, _, _ in model.jumps] + [float(grid[-1])]
    state = (model.x0.copy(), model.v0.copy())
    pieces: list[Result] = []
    failed = None

    def run(times: np.ndarray) -> Result | None:
        nonlocal state, failed
        piece = solve(dataclasses.replace(model, x0=state[0], v0=state[1], jumps=()), times)
        pieces.append(piece)
        if not piece.success:
            failed = piece
            return None
        state = (piece.displacement[-1].copy(), piece.velocity[-1].copy())
        return piece

    for i in range(len(bounds) - 1):
        ta, tb = bounds[i], bounds[i + 1]
        last = i == len(bounds) - 2
        lo = int(np.searchsorted(grid, ta, side="left"))
        hi = N if last else int(np.searchsorted(grid, tb, side="left"))
        t = ta
        if lo < hi:
            if grid[lo] > ta and run(np.array([ta, grid[lo]])) is None:
                break
            x[lo], v[lo] = state
            if hi - lo > 1:
                piece = run(grid[lo:hi])
                if piece is None:
                    break
                x[lo:hi], v[lo:hi] = piece.displacement, piece.velocity
            t = float(grid[hi - 1])
        if last:
            break
        if tb > t and run(np.array([t, tb])) is None:
            break
        _, dx, dv = model.jumps[i]
        state = (state[0] + dx, state[1] + dv)
    first = pieces[0].stats
    counts = {key: sum(getattr(p.stats, key) for p in pieces)
              for key in ("nfev", "njev", "nlu", "steps_accepted", "steps_rejected", "wall_time_s")}
    message = (failed.stats.message if failed is not None else
               f"{first.message}; restarted at {len(model.jumps)} jump(s) of the ground's displacement or velocity")
    stats = dataclasses.replace(first, **counts, success=failed is None, message=message,
                                stated_accuracy=max(p.stats.stated_accuracy for p in pieces))
    notes = tuple(dict.fromkeys(note for p in pieces for note in p.notes))
    return make_result(model, grid, x, v, stats, t_failed=None if failed is None else failed.t_failed, notes=notes)


def ground_history(model: Model, grid: np.ndarray, solve: Callable[..., Result]) -> GroundHistory:
    """The ground's displacement, velocity and acceleration on the grid: evaluated where given, else integrated
    from rest (a free unit mass driven by the acceleration, with the velocity's jumps), exactly where the signal
    has an exact generator."""
    g = model.ground
    zeros = np.zeros(len(grid))
    acceleration = g.acceleration.value(grid) if g.acceleration is not None else zeros
    if g.quantity == "displacement":
        velocity = g.velocity.value(grid) if g.velocity is not None else zeros
        return GroundHistory(g.given.value(grid), velocity, acceleration, g.quantity)
    free = Model(dofs=("ground",), M=np.ones((1, 1)), C=np.zeros((1, 1)), K=np.zeros((1, 1)),
                 x0=np.array([g.u0]), v0=np.array([g.v0]),
                 signals=(g.acceleration,) if g.acceleration is not None else (), force_dofs=(0,) if
                 g.acceleration is not None else (), source=model.source,
                 jumps=tuple((t, np.zeros(1), np.array([dv])) for t, _, dv in g.jumps))
    exact = g.acceleration is None or g.acceleration.exo() is not None
    span = float(grid[-1] - grid[0])
    size = max(np.abs(acceleration).max(initial=0.0) * span * span, abs(g.v0) * span, abs(g.u0), 1e-300)
    tol = Tolerances(rtol=GROUND_RTOL, atol=GROUND_RTOL * size)
    result = solve(free, grid, "exact" if exact else "DOP853", tol)
    velocity = g.velocity.value(grid) if g.velocity is not None else result.velocity[:, 0]
    return GroundHistory(result.displacement[:, 0], velocity, acceleration, g.quantity,
                         integrated_accuracy=result.stats.stated_accuracy)


def drift_note(model: Model, history: GroundHistory) -> str | None:
    """A warning where a ground acceleration's integrated velocity or displacement ends far from rest: a record's
    baseline left uncorrected, or a shape given as an acceleration whose mean from rest is not zero (a sine from
    rest has mean velocity a / omega: the ground walks away). None for a shock pulse, whose velocity change (the
    shock test's delta-v) is the test."""
    from smdcli.scenario.records import velocity_drift
    from smdcli.shapes import SHAPES

    if model.ground is None or model.ground.quantity != "acceleration" or SHAPES[model.ground.kind].shock:
        return None  # a shock pulse's velocity change is what it means
    line = velocity_drift("ground_motion", history.velocity, history.displacement)
    if line is None or model.ground.record:
        return line
    return (line.split(": a baseline")[0].replace("from the record", "from the ground acceleration") + f"; a {model.ground.kind} ground acceleration from rest has a mean "
            "velocity, so the ground drifts: give it as a displacement (quantity = \"displacement\") if the ground "
            "should oscillate in place")


def record_end_note(model: Model, grid: np.ndarray) -> str | None:
    """A warning where a record ends before the run does: what the ground does after it, and the other choice."""
    g = model.ground
    if g is None or not g.record or not len(grid) or g.given.end >= float(grid[-1]):
        return None
    end, last = g.given.end, float(g.given.v[-1])
    if g.given.ended:
        return (f"warning: ground_motion: the record ends at t = {end:g} s, before the run's end at "
                f"{float(grid[-1]):g} s: zero ground acceleration from then on (its last sample {last:.4g} m/s^2), the "
                "ground moving on at the velocity it reached; hold = true in [ground_motion] holds the last value")
    return (f"warning: ground_motion: the record ends at t = {end:g} s, before the run's end at {float(grid[-1]):g} s: "
            f"its last value {last:.4g} m/s^2 held to the end (hold = true)")
