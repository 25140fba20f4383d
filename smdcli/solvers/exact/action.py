"""Exact solution of large linear scenes that modal coordinates do not decouple: the exponential's action.

Where damping is not proportional (a damper at one end of a chain, dampers on some springs only) the undamped
modes do not decouple the scene, but its state matrix stays sparse: an element model has a few entries per row.
Its exponential is dense, though: for a 1,000-mass chain the dense path (linear.py) spends 1.4 s on expm of size
2,002 and then moves a 32 MB propagator through memory at every output step. Here exp(A dt) z is applied to the
state alone by the truncated Taylor series of Al-Mohy and Higham ("Computing the action of the matrix
exponential", SIAM J. Sci. Comput. 33, 2011): s sub-steps of at most m terms, (m, s) chosen so that the
truncation's backward error stays below the unit roundoff, exact to rounding as the Pade approximant of scipy's
expm is, at O(nnz) a term. The parameters come from the exact 1-norm of the balanced, shifted matrix, not from a
randomized estimate, so a run gives the same bits every time. The augmented system [[A, G], [0, S]] and the
reseeding of the force generators at every output point and force discontinuity are those of the dense path.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.model import Model
from smdcli.solvers.base import UNIT_ROUNDOFF, segments, stated_rounding, walk
from smdcli.text import plural

ACTION_DOFS = 64  # from this many DOFs a non-classically damped scene may take this path
# theta_m: the largest ||A dt|| / s for which m Taylor terms leave a backward error below 2^-53 (Al-Mohy and
# Higham 2011, Table 3.1; Higham, Functions of Matrices, Table A.3).
THETA = {1: 2.29e-16, 2: 2.58e-8, 3: 1.39e-5, 4: 3.40e-4, 5: 2.40e-3, 6: 9.07e-3, 7: 2.38e-2, 8: 5.00e-2,
         9: 8.96e-2, 10: 1.44e-1, 11: 2.14e-1, 12: 3.00e-1, 13: 4.00e-1, 14: 5.14e-1, 15: 6.41e-1, 16: 7.81e-1,
         17: 9.31e-1, 18: 1.09, 19: 1.26, 20: 1.44, 21: 1.62, 22: 1.82, 23: 2.01, 24: 2.22, 25: 2.43, 26: 2.64,
         27: 2.86, 28: 3.08, 29: 3.31, 30: 3.54, 35: 4.7, 40: 6.0, 45: 7.2, 50: 8.5, 55: 9.9}
# Seconds per entry of a sparse product and per Python-level product: measured on a 2-core machine, where they
# predicted 0.10-0.18 s for chains of 100-1,000 masses within 10-40 % (over, never under).
_SPARSE_ENTRY_S, _SPARSE_CALL_S = 1.5e-9, 6e-6


class Action:
    """The balanced, shifted sparse augmented matrix of a model and its Taylor parameters per step length."""

    def __init__(self, model: Model):
        import scipy.sparse as sparse

        n = model.n
        exos = [s.exo() for s in model.signals]
        m = sum(e.S.shape[0] for e in exos)
        self.n, self.size = n, 2 * n + m
        state = sparse.csr_array(model.state_matrix)  # the dense matrix is scanned once; no dense temporaries
        stiffness = float(abs(state[n:, :n]).sum(axis=0).max(initial=0.0))  # ||M^-1 K||_1
        blocks = []
        G = np.zeros((2 * n, m))
        S = np.zeros((m, m))
        col = 0
        for j, (signal, exo) in enumerate(zip(model.signals, exos)):
            k = exo.S.shape[0]
            S[col:col + k, col:col + k] = exo.S
            G[:, col:col + k] = np.outer(model.input_matrix[:, j], exo.g)
            blocks.append((2 * n + col, 2 * n + col + k, signal))
            col += k
        scale = balancing(stiffness, float(np.abs(G).sum(axis=0).max(initial=0.0)), n, self.size)
        A = sparse.bmat([[state, sparse.csr_array(G)], [None, sparse.csr_array(S)]], format="csr")
        A = sparse.csr_array(sparse.diags_array(1.0 / scale) @ A @ sparse.diags_array(scale))
        self.mu = float(A.diagonal().sum()) / self.size  # shifted by the mean eigenvalue, restored as e^(mu dt)
        self.A = sparse.csr_array(A - self.mu * sparse.eye_array(self.size, format="csr"))
        self.A.sum_duplicates()
        self.norm = float(np.abs(self.A).sum(axis=0).max(initial=0.0))
        self.scale = scale
        self.blocks = blocks
        self._parameters: dict[float, tuple[int, int]] = {}

    def parameters(self, dt: float) -> tuple[int, int]:
        """(m, s): the fewest products m s with ||A dt|| / s <= theta_m."""
        if dt not in self._parameters:
            self._parameters[dt] = taylor_parameters(self.norm * dt)
        return self._parameters[dt]

    def products(self, dt: float) -> int:
        """Sparse products one step of dt takes at most."""
        m, s = self.parameters(dt)
        return m * s

    def step(self, z: np.ndarray, dt: float) -> np.ndarray:
        """exp(A dt) z for a scaled state z."""
        m, s = self.parameters(dt)
        eta = math.exp(self.mu * dt / s)
        tol = UNIT_ROUNDOFF
        for _ in range(s):
            term = z
            c1 = np.abs(term).max(initial=0.0)
            total = z.copy()
            for j in range(m):
                term = (dt / (s * (j + 1))) * (self.A @ term)
                c2 = np.abs(term).max(initial=0.0)
                total += term
                if c1 + c2 <= tol * np.abs(total).max(initial=0.0):  # the series has converged (their 3.2)
                    break
                c1 = c2
            z = eta * total
        return z


def balancing(stiffness: float, force_norm: float, n: int, size: int) -> np.ndarray:
    """The diagonal scaling of the augmented state: x by 2^-e with 2^e ~ sqrt(||M^-1 K||_1) (the x and v columns
    of comparable size), the generators' states so that the force columns (force_norm: their 1-norm) are no larger.
    Powers of two: the scaling itself is exact."""
    scale = np.ones(size)
    scale[:n] = 2.0 ** -round(0.5 * math.log2(stiffness)) if stiffness > 0 else 1.0
    if force_norm > 0:
        scale[2 * n:] = 2.0 ** math.floor(math.log2(max(1.0, math.sqrt(stiffness)) / force_norm))
    return scale


def taylor_parameters(norm_dt: float) -> tuple[int, int]:
    """(m, s): the fewest products m s with ||A dt||_1 / s <= theta_m."""
    if norm_dt == 0:
        return 0, 1
    return min(((m, max(1, math.ceil(norm_dt / theta))) for m, theta in THETA.items()),
               key=lambda ms: (ms[0] * ms[1], ms[0]))


def dense_action_cost(Aaug: np.ndarray, n: int, model: Model, grid: np.ndarray) -> float:
    """action_cost of the model without building its sparse action: its norm and entries from the augmented matrix
    Aaug ([[A, G], [0, S]], linear.augmented's), balanced and shifted as Action's (a stacked sensitivity system's
    choice, where Action's sparse build cost 7 ms of a 30-mass chain's two sensitivities)."""
    size = len(Aaug)
    stiffness = float(np.abs(Aaug[n:2 * n, :n]).sum(axis=0).max(initial=0.0))
    scale = balancing(stiffness, float(np.abs(Aaug[:2 * n, 2 * n:]).sum(axis=0).max(initial=0.0)), n, size)
    balanced = Aaug * (scale[None, :] / scale[:, None])
    mu = float(np.trace(balanced)) / size
    balanced[np.diag_indices(size)] -= mu
    norm = float(np.abs(balanced).sum(axis=0).max(initial=0.0))
    N = len(grid)
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    m, s = taylor_parameters(norm * h)
    breaks = len(model.breakpoints(float(grid[0]), float(grid[-1])))
    return (N + 2 * breaks) * m * s * ((np.count_nonzero(balanced) + 4 * size) * _SPARSE_ENTRY_S + _SPARSE_CALL_S)


def action_cost(action: Action, model: Model, grid: np.ndarray) -> float:
    """Estimated seconds of the sparse action on this grid: products, each a pass over the entries and the state."""
    N = len(grid)
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    breaks = len(model.breakpoints(float(grid[0]), float(grid[-1])))
    products = (N + 2 * breaks) * action.products(h)
    return products * ((action.A.nnz + 4 * action.size) * _SPARSE_ENTRY_S + _SPARSE_CALL_S)


def solve_action(model: Model, grid: np.ndarray, action: Action | None = None
                 ) -> tuple[np.ndarray, np.ndarray, float, str]:
    """Displacement and velocity (N, n) on the grid, the stated accuracy and a description."""
    action = action or Action(model)
    n, N = model.n, len(grid)
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    scale = action.scale

    def reseed(z: np.ndarray, t: float) -> None:
        for lo, hi, signal in action.blocks:
            z[lo:hi] = signal.exo_state(t) / scale[lo:hi]

    out = np.empty((N, 2 * n))
    z = np.zeros(action.size)
    z[:n], z[n:2 * n] = model.x0 / scale[:n], model.v0
    substeps = 0
    for t, dt, k in walk(model, grid):  # w reseeded from its closed form at every step: no drift in the forcing
        reseed(z, t)
        if dt > 0:
            z = action.step(z, dt)
            substeps += action.parameters(dt)[1]
        if k is not None:
            out[k] = z[:2 * n]
    x, v = out[:, :n] * scale[:n], out[:, n:]
    m_h, s_h = action.parameters(h)
    # Each sub-step sums at most m terms whose sizes add up to e^(||A|| dt / s) times the state's.
    growth = m_h * math.exp(action.norm * h / s_h) if N > 1 else 1.0
    segs = len(segments(model, grid))
    stated = stated_rounding(substeps + segs, growth)
    message = (f"ok: exponential's action on the sparse state matrix ({action.A.nnz} entries of {action.size}^2; "
               f"damping not proportional), {plural(segs, 'force segment')}, "
               f"{m_h} Taylor terms x {s_h} sub-step{'s' if s_h != 1 else ''} per output step")
    return x, v, stated, message
