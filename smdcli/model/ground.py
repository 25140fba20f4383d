"""Support motion: what a moving ground does to the motion relative to it.

With y = x - 1 u_g (every DOF measured from the moving support), the ground's acceleration a_g enters the
equation of motion as the effective force -M 1 a_g:

    M y'' + C y' + K y + f_nl(y, y') = f(t) - M 1 a_g(t),

which is what uniform support excitation means: every element to ground moves with it, internal elements feel
only relative motion, and nonlinear elements see relative motion. A ground motion given as a displacement or a
velocity is differentiated exactly (harmonics, Fourier series, tables, expressions term by term). Where the
given quantity jumps (a step, a pulse or a square wave of displacement; a table's kinks), its derivative holds
an impulse: the relative state jumps there instead, by

    dy = -du 1,    dy' = -dv 1 + M^-1 C 1 du,

(the absolute position is continuous; a damper to ground passes the impulse c du to its mass), and the
integration restarts from the new state.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.shapes import Signal, build_signal
from smdcli.model.mass import mass_solve
from smdcli.scenario import GroundMotionSpec

# Ground jumps one run may restart at: each is a restart of the integration.
MAX_JUMPS = 100_000


@dataclass(frozen=True)
class GroundMotion:
    """The support's motion: the quantity given, its derivatives as signals (None where zero), the jumps of its
    displacement and velocity inside the run (t, du, dv), and its displacement and velocity at the start."""

    quantity: str
    kind: str  # the shape's type as the scenario names it: sine, pulse, table...
    given: Signal
    velocity: Signal | None  # given or derived; None for an acceleration, whose velocity is integrated
    acceleration: Signal | None
    jumps: tuple[tuple[float, float, float], ...]
    u0: float
    v0: float
    record: bool  # an acceleration table: its integrated velocity is checked for drift

    @property
    def exact(self) -> bool:
        """Whether every signal has an exact generator (an exact solve stays exact)."""
        return all(s is None or s.exo() is not None for s in (self.given, self.velocity, self.acceleration))


def ground_motion(spec: GroundMotionSpec, start: float, end: float, source: str = "<scenario>") -> GroundMotion:
    """The ground motion of a validated [ground_motion] over the run [start, end]; ScenarioError (naming `source`)
    for one that jumps more often than a run can restart, or whose derivatives are too large to evaluate."""
    from smdcli.expression import ExpressionError

    try:
        return _ground_motion(spec, start, end)
    except TooManyJumps as exc:
        raise ScenarioError(source, "ground_motion", f"the ground's displacement or velocity jumps {exc.count:.3g} "
                            f"times or more in the run (limit {MAX_JUMPS}); each is a restart") from None
    except InfiniteJump as exc:
        raise ScenarioError(source, "ground_motion", f"the ground's {spec.quantity} or its derivative jumps by an "
                            f"amount that is not a finite number at t = {exc.time:g} s (infinite on a side); "
                            "expected finite values on both sides of each jump") from None
    except ExpressionError as exc:
        raise ScenarioError(source, "ground_motion.expr", f"{exc}; a {spec.quantity} is differentiated to the "
                            "ground's acceleration") from None


class InfiniteJump(ValueError):
    """A ground motion whose jump at `time` is not a finite number (its value on a side is infinite)."""

    def __init__(self, time: float):
        self.time = time


class TooManyJumps(ValueError):
    """A ground motion that jumps more than MAX_JUMPS times in the run; `count` is how many were seen (at least)."""

    def __init__(self, count: float):
        self.count = count
        super().__init__(f"{count:.3g} jumps")


def _ground_motion(spec: GroundMotionSpec, start: float, end: float) -> GroundMotion:
    given = build_signal(spec.shape)
    jumps: dict[float, list[float]] = {}
    if spec.quantity == "acceleration":
        if not spec.hold:  # a record is over at its last sample
            given = given.as_record()
        velocity, acceleration, u0, v0 = None, given, 0.0, 0.0
    elif spec.quantity == "velocity":
        velocity = given
        acceleration, velocity_jumps = derivative(given, start, end)
        for t, dv in velocity_jumps:
            jumps.setdefault(t, [0.0, 0.0])[1] += dv
        u0, v0 = 0.0, float(given.value(start))
    else:
        velocity, displacement_jumps = derivative(given, start, end)
        acceleration, velocity_jumps = derivative(velocity, start, end) if velocity is not None else (None, [])
        for t, du in displacement_jumps:
            jumps.setdefault(t, [0.0, 0.0])[0] += du
        for t, dv in velocity_jumps:
            jumps.setdefault(t, [0.0, 0.0])[1] += dv
        u0 = float(given.value(start))
        v0 = float(velocity.value(start)) if velocity is not None else 0.0
    ordered = tuple((t, du, dv) for t, (du, dv) in sorted(jumps.items()) if du != 0.0 or dv != 0.0)
    return GroundMotion(spec.quantity, spec.shape.type, given, velocity, acceleration, ordered, u0, v0,
                        record=spec.quantity == "acceleration" and spec.shape.type == "table")


def derivative(signal: Signal, start: float, end: float) -> tuple[Signal | None, list[tuple[float, float]]]:
    """d/dt of a signal between its jumps (None where that is zero), and its jumps (t, size) inside (start, end);
    TooManyJumps, counted before any is listed, past MAX_JUMPS."""
    count = signal.edge_count(start, end, MAX_JUMPS)
    if not count <= MAX_JUMPS:
        raise TooManyJumps(count)
    edges = signal.breakpoints(start, end)
    with np.errstate(all="ignore"):  # a jump between infinities is not a number: refused below, not warned
        jumps = [(float(t), float(signal.value(t) - signal.value_left(t))) for t in edges]
    for t, size in jumps:
        if not np.isfinite(size):
            raise InfiniteJump(t)
    jumps = [(t, size) for t, size in jumps if size != 0.0]
    return signal.derivative(start), jumps


def state_jumps(ground: GroundMotion, M: np.ndarray, C: np.ndarray) -> tuple[tuple[float, np.ndarray, np.ndarray], ...]:
    """The relative state's jumps (t, dx, dv) where the ground's displacement or velocity jumps (see ground.py)."""
    ones = np.ones(M.shape[0])
    impulse = mass_solve(M, (C @ ones)[:, None])[:, 0]  # a damper to ground passes c du to its mass
    return tuple((t, -du * ones, -dv * ones + impulse * du) for t, du, dv in ground.jumps)
