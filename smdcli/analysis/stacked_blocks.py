"""The stacked sensitivity system's blocks (model_derivative.augmented_model's): each parameter's derivatives of M, C
and K, and every block's acceleration from its displacement and velocity, by the scene's own equation.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.model import Model
from smdcli.model.sparse import cheapest, rows_times


def stacked_blocks(stacked: Model, n: int, P: int):
    """The stacked model's (augmented_model's) parameters' dM, dC, dK (P, n, n), its input columns per block (P + 1,
    n, F) and the blocks' initial states (P, n) of x and v."""
    def below(matrix):
        return np.stack([matrix[(i + 1) * n:(i + 2) * n, :n] for i in range(P)])
    dense = stacked.dense()
    columns = stacked.inputs.reshape(P + 1, n, -1)
    return (below(dense.M), below(dense.C), below(dense.K), columns, stacked.x0[n:].reshape(P, n),
            stacked.v0[n:].reshape(P, n))


def block_accelerations(base: Model, values: np.ndarray, u: np.ndarray, columns: np.ndarray, dM: np.ndarray,
                   dC: np.ndarray, dK: np.ndarray, scales: np.ndarray) -> None:
    """Each block's acceleration from its displacement and velocity (values: (quantities, P + 1, N, n), x, v then a),
    in place, by the scene's own M a = F - C v - K x (Model.acceleration, each matrix as it multiplies cheapest): a
    parameter's block driven by B_i u and the scene's - dM a - dC v - dK x (a parameter's few entries: O(n) a time,
    not a dense product). u (N, F): the stacked model's forces at each time; columns, dM, dC, dK: stacked_blocks'."""
    x, v, a = values
    a[0] = base.acceleration(x[0], v[0], u @ columns[0].T)
    for i, scale in enumerate(scales):
        driven = u @ columns[i + 1].T
        for matrix, of in ((dM[i], a[0]), (dC[i], v[0]), (dK[i], x[0])):
            if matrix.any():
                driven -= rows_times(of, cheapest(matrix).T)
        a[i + 1] = base.acceleration(x[i + 1], v[i + 1], driven / scale)


def accelerations_after(base: Model, stacked: Model, values: np.ndarray, grid: np.ndarray, scales: np.ndarray) -> None:
    """Each block's acceleration from its x and v on the grid (block_accelerations), in place, the stacked model's
    forces evaluated there (a sample on a jump its right limit, as the signal gives it)."""
    dM, dC, dK, columns, _, _ = stacked_blocks(stacked, base.n, len(scales))
    forces = np.empty((len(grid), len(stacked.signals)))
    for j, signal in enumerate(stacked.signals):
        forces[:, j] = signal.value(grid)
    block_accelerations(base, values, forces, columns, dM, dC, dK, scales)
