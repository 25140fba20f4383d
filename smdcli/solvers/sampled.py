"""Linear scenes driven by tabulated forces (a record, a first-order hold) whose samples and output points fall on
one uniform grid of knots: the exact recurrence from knot to knot, taken in blocks.

Between two knots every force is linear in time (a table's first-order hold) or constant (its previous-value hold),
so one step is exact: y_(k+1) = E y_k + G w_k, with E and G from one exponential of the augmented system (exact.py)
and w_k = (value, slope) each table's right limit at knot k. The dense path reseeds w at every breakpoint, one
Python step per sample (15 ms for 2,001 samples of a 3-DOF frame, 78 ms to integrate a 4,001-sample record to the
ground's displacement); here the steps run J at a time across all blocks at once (the forced part of each block),
the blocks' starts one after another, and each block's free part as one product with the stacked powers E^j:
about 2 sqrt(steps) Python steps. The rounding is the dense path's: powers up to E^J, a restart every block.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.model import Model
from smdcli.model.forcing import Table
from smdcli.solvers.accurate_expm import expm_times, needed
from smdcli.text import plural

BLOCK = 64  # steps a block takes at most


def uniform_knots(model: Model, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(knots, the times just after which the forces are read at each, where the grid's points are among the knots):
    the output points and the tables' samples between them, where they are evenly spaced; else None. A sample within
    rounding of an output point is that point, the forces read at the later of the two: a previous-value hold's new
    value, a first-order hold's new slope."""
    t0, t1 = float(grid[0]), float(grid[-1])
    samples = model.breakpoints(t0, t1)
    same = 8 * np.spacing(max(abs(t0), abs(t1)))  # a sample and an output point apart by the times' rounding
    after = np.clip(np.searchsorted(grid, samples), 1, len(grid) - 1)
    below, above = samples - grid[after - 1], grid[after] - samples
    apart = np.minimum(below, above) > same
    knots = np.union1d(grid, samples[apart])
    if len(knots) < 2:
        return None
    h = (t1 - t0) / (len(knots) - 1)
    if np.abs(np.diff(knots) - h).max() > same:
        return None
    read_at = knots.copy()
    nearest = np.where(below <= above, after - 1, after)[~apart]
    where = np.searchsorted(knots, grid[nearest])
    np.maximum.at(read_at, where, samples[~apart])
    return knots, read_at, np.searchsorted(knots, grid)


def applies(model: Model) -> bool:
    """Every force a table."""
    return bool(model.signals) and all(isinstance(s, Table) for s in model.signals)


def solve_sampled(model: Model, grid: np.ndarray, Aaug: np.ndarray, blocks) -> tuple | None:
    """x, v (N, n), the stated accuracy and a description, or None where the knots are not evenly spaced;
    Aaug and blocks: exact.augmented's."""
    from scipy.linalg import expm

    from smdcli.solvers.base import stated_rounding

    found = uniform_knots(model, grid)
    if found is None:
        return None
    knots, read_at, rows = found
    n, s, size = model.n, 2 * model.n, Aaug.shape[0]
    steps = len(knots) - 1
    h = (float(knots[-1]) - float(knots[0])) / steps
    norm_A = float(np.abs(Aaug).sum(axis=0).max(initial=0.0))
    accurate = needed(norm_A * h, size)
    propagator = expm_times(Aaug, h) if accurate else expm(Aaug * h)
    E, G = propagator[:s, :s], propagator[:s, s:]
    w = np.empty((steps, size - s))
    for lo, hi, signal in blocks:
        w[:, lo - s:hi - s] = signal.exo_states(read_at[:-1])
    J = min(BLOCK, steps)
    count = -(-steps // J)
    forced = np.zeros((count * J, s))
    forced[:steps] = w @ G.T
    forced = forced.reshape(count, J, s)
    within = np.zeros((count, J + 1, s))  # each block's forced response from rest
    for j in range(J):
        within[:, j + 1] = within[:, j] @ E.T + forced[:, j]
    powers = np.empty((J + 1, s, s))
    powers[0] = np.eye(s)
    for j in range(J):
        powers[j + 1] = powers[j] @ E
    starts = np.empty((count + 1, s))
    starts[0, :n], starts[0, n:] = model.x0, model.v0
    for b in range(count):
        starts[b + 1] = powers[J] @ starts[b] + within[b, J]
    states = np.einsum("jst,bt->bjs", powers[:J], starts[:count]) + within[:, :J]
    states = np.concatenate([states.reshape(count * J, s), starts[count:]])[rows]
    stated = stated_rounding(2 * J + count, 1.0 if accurate else norm_A * h)
    message = (f"ok: {plural(steps, 'step')} between the tables' samples and the output points, each exact for "
               f"the tables' first-order hold, {math.ceil(steps / J)} blocks of {J} (one matrix exponential of size "
               f"{size}{' in double-double, a stiff scene' if accurate else ''})")
    return states[:, :n].copy(), states[:, n:].copy(), stated, message
