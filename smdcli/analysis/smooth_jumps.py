"""A smooth nonlinear scene's sensitivities under the ground's jumps (a rectangle pulse of its velocity or
displacement): the sensitivity equations integrated from jump to jump (smooth_sensitivity.py), the state jumped by
the ground's jump at each and its sensitivities by each parameter's derivative of the jump (a pulse's amplitude; a
mass or a damper to ground through the impulse c du it passes), as solvers/ground.across_jumps restarts the
forward run. A sample on a jump is its right limit, as there.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from smdcli.analysis.signal_derivative import combined
from smdcli.errors import UsageError
from smdcli.model import Model
from smdcli.solvers.ground import jump_at


def across_ground_jumps(model: Model, derivatives: list, scales: np.ndarray, grid: np.ndarray, rtol: float,
                        advance, smooth_sensitivities):
    """smooth_sensitivities' (y, S, y', S', rates_at, method) for a scene whose ground jumps within the grid, each
    piece between two jumps by smooth_sensitivities itself (from the state and sensitivities it is handed)."""
    N, n, P = len(grid), model.n, len(derivatives)
    inside = [(t, dx, dv) for t, dx, dv in model.jumps if grid[0] < t <= grid[-1]]
    bounds = [float(grid[0])] + [t for t, _, _ in inside] + [float(grid[-1])]
    smooth = dataclasses.replace(model, jumps=())
    y = S = rates = d_rates = None
    start, pieces, method = None, [], ""
    for i, (ta, tb) in enumerate(zip(bounds[:-1], bounds[1:])):
        last = i == len(bounds) - 2
        lo = int(np.searchsorted(grid, ta, side="left"))
        hi = N if last else int(np.searchsorted(grid, tb, side="left"))
        times = np.unique(np.concatenate([[ta], grid[lo:hi], [tb]]))  # the piece's samples, joined to its ends
        y_p, S_p, r_p, d_p, rates_at, method = smooth_sensitivities(smooth, derivatives, scales, times, rtol,
                                                                    start=start)
        if y is None:
            y, S, rates, d_rates = (np.full((N, *q.shape[1:]), np.nan) for q in (y_p, S_p, r_p, d_p))
        at = np.searchsorted(times, grid[lo:hi])
        y[lo:hi], S[lo:hi], rates[lo:hi], d_rates[lo:hi] = y_p[at], S_p[at], r_p[at], d_p[at]
        pieces.append((ta, rates_at))
        if advance is not None:
            advance(hi - lo)
        if last:
            break
        after, moved = y_p[-1].copy(), S_p[-1].copy()
        after[:2 * n] += _jump(model, tb)
        for p, (d, scale) in enumerate(zip(derivatives, scales)):
            moved[:2 * n, p] += combined(d.weights * scale, [_jump(m, tb) for m in d.models])
        start = (after, moved)
    starts = np.array([a for a, _ in pieces])

    def rates_at(t: float, left: bool = False) -> tuple[np.ndarray, np.ndarray]:
        index = max(int(np.searchsorted(starts, t, side="left" if left else "right")) - 1, 0)
        return pieces[index][1](t, left)
    rates_at.breaks = np.union1d(np.concatenate([r.breaks for _, r in pieces]), starts[1:])
    del P
    return y, S, rates, d_rates, rates_at, method


def _jump(model: Model, t: float) -> np.ndarray:
    """The ground's jump at t in this model (ground.jump_at); one the parameter moves in time is refused (as
    model_derivative refuses it before this is reached)."""
    try:
        return jump_at(model, t)
    except LookupError:
        raise UsageError(f"{model.source}: the ground's jump at t = {t:.6g} s moves with the parameter") from None
