"""What a solver is: a name, what it can handle, its order, and solve(model, grid).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import partial
from typing import Callable, ClassVar

import numpy as np

from smdcli.model import Model
from smdcli.model.accuracy import loaded_force
from smdcli.result import NonsmoothHistory, Result, SolverStats, finite_peak


# A state larger than this (relative to the initial and forced scale) has diverged.
GROWTH_BOUND = 1e8
MAX_STEPS = 2_000_000
TIME_ONCE_S = 0.2  # runs longer than this are timed once, not repeated: their noise is a small share of them


@dataclass(frozen=True)
class Tolerances:
    """The accuracy a run asks for: relative and absolute error, a fixed step and method parameters where used."""

    rtol: float = 1e-6
    atol: float = 1e-9
    dt: float | None = None
    options: tuple[tuple[str, float | str], ...] = ()  # method parameters: beta, gamma, scheme, alpha, rho_inf
    max_steps: int | None = None  # step budget; None: the solver's own limit
    breakpoints: bool = True  # restart adaptive methods at force discontinuities (False only for study)
    balance: bool = True  # rerun a nonsmooth scene's integrator tighter until its energy balance holds (False: study)


class Solver:
    """A method: refuse() says why it cannot take a model; solve() returns a Result."""

    name: ClassVar[str]
    family: ClassVar[str]
    description: ClassVar[str] = ""
    linear_only: ClassVar[bool] = False
    adaptive: ClassVar[bool] = True
    # an adaptive method's step control holds the root mean square of the state's local errors to the tolerance
    # (scipy's norm, and the compiled kernels'), not each component's: stated_tolerance's sqrt(states)
    rms_error_norm: ClassVar[bool] = True
    # low order (3 or less, or a variable order from 1: BDF, LSODA, ode113): the global error outgrows that statement
    # at tight tolerances (ode23t 100x at rtol 1e-8 on a 3-mass chain), so it is measured by a rerun at a tenth of them
    measured_error: ClassVar[bool] = False
    implicit: ClassVar[bool] = False
    order: ClassVar[int | None] = None
    compiled: ClassVar[bool] = False  # stepped by a compiled kernel: ~100x cheaper per step than a Python-driven one

    def refuse(self, model: Model) -> str | None:
        """Why this solver cannot take the model, with what to use instead; None if it can."""
        if self.linear_only and not model.is_linear:
            first = model.nonlinear_paths[0]
            return (f"{self.name!r} needs a linear model; {first} is nonlinear; "
                    "try 'DOP853', 'Radau' or 'auto'")
        return None

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        """Integrate the model over the grid."""
        raise NotImplementedError


UNIT_ROUNDOFF = 2.0**-53


def stated_rounding(operations: int, growth: float = 1.0) -> float:
    """The error, relative to the peak, that rounding can leave after `operations` dependent steps, each
    amplifying it by up to `growth` (the norm a matrix exponential was squared from): 8 u N growth."""
    return 8 * UNIT_ROUNDOFF * max(operations, 1) * max(growth, 1.0)


def stated_tolerance(rtol: float | None, atol: float | None, peak: float, states: int = 1,
                     speed: float = 0.0) -> float:
    """What an adaptive method's tolerances let the global error reach, relative to the peak of x and, where the
    velocity's peak `speed` is given and smaller, of v (atol is absolute in each): 10 sqrt(states) (rtol + atol /
    peak).

    The step control holds the root mean square of the local errors over the state's `states` components to the
    tolerance, which lets one component's error reach sqrt(states) times it (a chain where a wave moves a few of its
    masses); and local error control does not bound the global error: ten times the tolerance is the margin measured
    on the bundled scenes (tests/test_golden.py checks every golden against a tighter method), the absolute part's as
    the relative part's (DOP853 at rtol 1e-10 and atol 1e-9 on a 300-mass chain with a cubic spring: 1.4e-7 of the
    peak off where rtol + atol / peak said 1.1e-8; tests/test_accuracy.py)."""
    margin = 10 * math.sqrt(max(states, 1))
    peak = min(peak, speed) if speed > 0 else peak
    return margin * ((rtol or 0.0) + (atol or 0.0) / peak) if peak > 0 else margin * (rtol or 0.0)


def make_result(model: Model, grid: np.ndarray, x: np.ndarray, v: np.ndarray, stats: SolverStats,
                t_failed: float | None = None, notes: tuple[str, ...] = (), force: np.ndarray | None = None,
                acceleration: np.ndarray | None = None, found_extremes: tuple = (),
                nonsmooth: NonsmoothHistory | None = None) -> Result:
    """A Result from displacement and velocity on the grid; acceleration derived where not given, and the applied
    force too, where first read unless the acceleration needs it; found_extremes: Result's, where the solver found
    them."""
    if acceleration is None:
        force = model.applied_force(grid) if force is None else force
        with np.errstate(all="ignore"):
            acceleration = model.acceleration(x, v, force)
    elif force is None:
        force = partial(model.applied_force, grid)  # Result.force: computed where first read
    return Result(time=grid, dofs=model.dofs, displacement=x, velocity=v, acceleration=acceleration,
                  force=force, stats=stats, t_failed=t_failed, notes=notes, found_extremes=found_extremes,
                  nonsmooth=nonsmooth)


def cuts(model: Model, grid: np.ndarray, breakpoints: bool = True) -> np.ndarray:
    """Start, force discontinuities (unless breakpoints is False) and end: where an integration restarts."""
    t0, t1 = float(grid[0]), float(grid[-1])
    inner = model.breakpoints(t0, t1) if breakpoints else np.empty(0)
    return np.concatenate([[t0], inner, [t1]])


def segments(model: Model, grid: np.ndarray) -> list[tuple[float, float]]:
    """The intervals between force discontinuities that cover the grid."""
    edges = cuts(model, grid).tolist()
    return list(zip(edges[:-1], edges[1:]))


def walk(model: Model, grid: np.ndarray) -> Iterator[tuple[float, float, int | None]]:
    """The exact recurrences' way over the grid and the force discontinuities: (t, dt, k), a propagation from t
    over dt that lands on grid point k, or on the next discontinuity where k is None. dt is 0 for a point the walk
    is already on, and exactly the grid's step h where a difference of grid times is h up to their rounding."""
    N = len(grid)
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    segs = segments(model, grid)
    k = 0
    for index, (ta, tb) in enumerate(segs):
        last = index == len(segs) - 1
        stop = N if last else int(np.searchsorted(grid, tb, side="left"))
        t = ta
        while k < stop:
            dt = float(grid[k] - t)
            yield t, (h if abs(dt - h) <= 1e-9 * h else dt), k
            t = float(grid[k])
            k += 1
        if not last and tb > t:
            yield t, tb - t, None


def force_function(model: Model, ta: float, tb: float) -> Callable[[float], np.ndarray]:
    """Force values on [ta, tb], taking left limits in the segment's second half so no jump leaks in."""
    mid = 0.5 * (ta + tb)
    signals = model.signals

    def u(t: float) -> np.ndarray:
        if t < mid:
            return np.array([float(s.value(t)) for s in signals])
        return np.array([float(s.value_left(t)) for s in signals])

    return u


def divergence_bound(model: Model, grid: np.ndarray) -> float:
    """GROWTH_BOUND times a size a bounded response stays within: initial state and static deflection."""
    scale = max(np.abs(model.x0).max(initial=0.0), np.abs(model.v0).max(initial=0.0), 1.0)
    if model.is_forced:
        peak_force = finite_peak(loaded_force(model)(grid))  # the other DOFs' forces are zero
        stiffness = np.abs(model.K.diagonal()).min(initial=0.0)  # dense or a sparse scene's CSR
        scale = max(scale, peak_force / stiffness if stiffness > 0 else peak_force * (grid[-1] - grid[0]) ** 2)
    return GROWTH_BOUND * scale


def diverged(y: np.ndarray, bound: float) -> str | None:
    """Why a state counts as diverged (NaN, inf, past the bound), or None."""
    if not np.all(np.isfinite(y)):
        return "the state became NaN or infinite"
    if np.abs(y).max() > bound:
        return f"the state grew past {bound:.3g}"
    return None
