"""Forces without an exact generator (a chirp, a formula: Signal.exo() is None) held linearly between samples, as
the exact solvers take them, and what the hold costs in accuracy and says.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from smdcli.model import Model
from smdcli.shapes.table import Table


def held_paths(model: Model) -> tuple[str, ...]:
    """The paths of the forces without an exact generator (Signal.exo() is None): those a hold stands in for."""
    return tuple(path for path, s in zip(model.force_paths, model.signals) if s.exo() is None)


def first_order_hold(model: Model, grid: np.ndarray) -> tuple[Model, tuple[str, ...]]:
    """Replace forces without an exact form (Signal.exact false) by their piecewise-linear interpolant on the grid."""
    held = held_paths(model)
    if not held:
        return model, held
    signals = tuple(s if s.exo() is not None else Table(grid, s.value(grid), "linear") for s in model.signals)
    return dataclasses.replace(model, signals=signals), held


def halved(grid: np.ndarray) -> np.ndarray:
    """The grid with the midpoint of each step added: its points are the even ones."""
    return subdivided(grid, 2)


def subdivided(grid: np.ndarray, per_step: int) -> np.ndarray:
    """The grid with per_step - 1 evenly spaced points added in each step (per_step a power of two: the fractions,
    and a midpoint's 0.5 a + 0.5 b, are exact): its points are every per_step-th."""
    if per_step == 1 or len(grid) < 2:
        return np.asarray(grid, dtype=float)
    fraction = np.arange(per_step) / per_step
    fine = (grid[:-1, None] * (1.0 - fraction) + grid[1:, None] * fraction).ravel()
    return np.append(fine, grid[-1])


def hold_response_error(x: np.ndarray, solved_on) -> float:
    """The hold's error in the response, relative to its peak: the run again with the forces held on the grid halved
    (solved_on(fine) -> its displacement), whose difference from the run is 3/4 of the run's error (O(step^2)). The
    force's own relative gap (hold_error) understated it by up to 1.2x where the dynamics amplify what the hold
    leaves out."""
    finer = solved_on()[::2]
    peak = max(float(np.abs(finer).max(initial=0.0)), 1e-300)
    return min(1.0, 4.0 / 3.0 * float(np.abs(x - finer).max(initial=0.0)) / peak)


def held_reason(model: Model, error: float) -> str:
    """A requested exact run's reason where it held a force: not the registry's "exact to rounding", the hold's
    error being the run's."""
    return (f"requested: matrix exponential, but {unheld(model)} has no exact integral and is held linearly between "
            f"output points: error about {error:.1e} of the peak, not rounding's ('auto' or 'DOP853' integrates it to "
            "the tolerance)")


def unheld(model: Model) -> str:
    """The forces without an exact integral, by path and type: 'force[0] (expression)'."""
    held = [f"{path} ({kind})" for path, kind, s in zip(model.force_paths, model.force_types, model.signals)
            if s.exo() is None]
    return ", ".join(held)


def hold_error(model: Model, grid: np.ndarray, held: tuple[str, ...]) -> float:
    """Relative size of the first-order hold's error: the held forces between grid points against their peak."""
    middle = halved(grid)[1::2]
    worst = 0.0
    for path, signal in zip(model.force_paths, model.signals):
        if path in held:
            values = signal.value(grid)
            gap = np.abs(signal.value(middle) - 0.5 * (values[1:] + values[:-1])).max(initial=0.0)
            worst = max(worst, gap / max(np.abs(values).max(initial=0.0), 1e-300))
    return min(1.0, worst)
