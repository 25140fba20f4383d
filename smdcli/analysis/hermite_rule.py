"""The quintic Hermite interpolant of a run's (x, v, a) over each output step, as the energy balance and the
dissipation objectives integrate on it: its basis' slopes, the exact integral of a quadratic power over a step (a Gram
form of the step's ends), and its rates at quadrature nodes.

Must not import: anything of smd above numpy (pure arithmetic on arrays).
"""

from __future__ import annotations

import numpy as np


def hermite_slopes(points: np.ndarray) -> np.ndarray:
    """d/ds of the quintic Hermite basis on s in [0, 1] for (x0, h v0, h^2 a0, x1, h v1, h^2 a1), (G, 6)."""
    coefficients = np.array([  # powers s^0 .. s^5
        [1, 0, 0, -10, 15, -6], [0, 1, 0, -6, 8, -3], [0, 0, 0.5, -1.5, 1.5, -0.5],
        [0, 0, 0, 10, -15, 6], [0, 0, 0, -4, 7, -3], [0, 0, 0, 0.5, -1, 0.5]])
    powers = points[:, None] ** np.arange(5)
    slopes = np.concatenate([np.zeros((len(points), 1)), powers * np.arange(1, 6)], axis=1)
    return slopes @ coefficients.T


def gram_power(gram: np.ndarray, h: np.ndarray, x, v, a) -> np.ndarray:
    """Each step's integral of <L x', R x'> on the Hermite interpolant of rows x, v, a ((L, R) pairs of the rows
    k - 1 and k of each step): the Gram form of (x1 - x0, h v0, h^2 a0, h v1, h^2 a1)."""
    (Lx, Rx), (Lv, Rv), (La, Ra) = x, v, a
    dL, dR = Lx[1:] - Lx[:-1], Rx[1:] - Rx[:-1]

    def dot(A, B):
        return np.einsum("ij,ij->i", A, B)

    vv, va, aa = dot(Lv, Rv), dot(Lv, Ra), dot(La, Ra)
    h2 = h * h
    products = {  # (i, j) of the basis: its inner product times the powers of h the ends carry
        (0, 0): dot(dL, dR), (0, 1): h * dot(dL, Rv[:-1]), (0, 2): h2 * dot(dL, Ra[:-1]),
        (0, 3): h * dot(dL, Rv[1:]), (0, 4): h2 * dot(dL, Ra[1:]),
        (1, 1): h2 * vv[:-1], (1, 2): h * h2 * va[:-1], (1, 3): h2 * dot(Lv[:-1], Rv[1:]),
        (1, 4): h * h2 * dot(Lv[:-1], Ra[1:]), (2, 2): h2 * h2 * aa[:-1], (2, 3): h * h2 * dot(La[:-1], Rv[1:]),
        (2, 4): h2 * h2 * dot(La[:-1], Ra[1:]), (3, 3): h2 * vv[1:], (3, 4): h * h2 * va[1:], (4, 4): h2 * h2 * aa[1:]}
    total = sum((gram[i, j] if i == j else 2 * gram[i, j]) * value for (i, j), value in products.items())
    return total / h


def node_rates(slope: np.ndarray, h: np.ndarray, x, v, a) -> np.ndarray:
    """The interpolant's rate at the Gauss nodes of each step, (steps, nodes, columns), from rows of x, v, a
    (projected: x P for the columns of P)."""
    ends = np.stack([x[1:] - x[:-1], h[:, None] * v[:-1], (h * h)[:, None] * a[:-1], h[:, None] * v[1:],
                     (h * h)[:, None] * a[1:]], axis=1)
    return np.einsum("gb,kbc->kgc", slope, ends) / h[:, None, None]
