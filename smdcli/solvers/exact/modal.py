"""Exact solution of large classically damped linear scenes in modal coordinates.

Where C M^-1 K = K M^-1 C (proportional damping, Caughey's condition) and every undamped mode has a positive
frequency, the undamped mode shapes Phi (K Phi = M Phi Omega^2, Phi^T M Phi = I, from a symmetric solver)
decouple the scene into n 1-DOF oscillators q_i'' + c_i q_i' + w_i^2 q_i = (Phi^T B u(t))_i. Each is advanced
exactly like the dense path (linear.py) advances the whole scene: its state augmented with the force generators'
state w, propagated by expm of a (2 + m)-square matrix, w reseeded from its closed form at every output point
and split at force discontinuities. Cost O(n) per output step and O(n^3) once (the eigenvectors; O(n^2) for a
chain, whose M^-1/2 K M^-1/2 is tridiagonal), against O(n^2) per step and a dense 2n-square exponential; the n
small exponentials are one vectorized Pade evaluation (expm_stack), taken once for a uniform grid. x = Phi q at
the end, one matrix product. Where every force is a table on one even grid of knots (a record), all modes step
from knot to knot in blocks instead (sampled.py).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.model import Model
from smdcli.solvers.exact import sampled
from smdcli.solvers.exact.accurate_expm import NEEDED_NORM, expm_stack, expm_times
from smdcli.solvers.base import segments, stated_rounding, walk
from smdcli.text import plural

MODAL_DOFS = 64  # from this many DOFs a classically damped scene is solved in modal coordinates


def modal_applies(model: Model) -> bool:
    """Large, classically damped, every force with an exact generator: the modal path serves it."""
    return (model.n >= MODAL_DOFS and model.is_linear and all(s.exo() is not None for s in model.signals)
            and model.proportional_damping and float(model.modes.natural_frequencies.min()) > 0)


def modal_coefficients(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mass-normalized shapes Phi (n, n) (Phi^T M Phi = I), each mode's squared frequency and damping (n,)."""
    shapes = model.modes.shapes
    C, K, _ = model.sparse
    squared = (shapes * (K @ shapes)).sum(axis=0)  # Rayleigh quotients: w_i^2
    damping = (shapes * (C @ shapes)).sum(axis=0)  # the diagonal of Phi^T C Phi, all there is of it
    return shapes, squared, damping


def mode_matrices(squared: np.ndarray, damping: np.ndarray, size: int = 2) -> np.ndarray:
    """Each mode's state matrix [[0, 1], [-w^2, -d]] (n, 2, 2), in the corner of a zero (n, size, size) for the
    generators' states beside it."""
    A = np.zeros((len(squared), size, size))
    A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = 1.0, -squared, -damping
    return A


def mode_propagators(A: np.ndarray, dt: float) -> np.ndarray:
    """expm(A_i dt) for a stack of modes' augmented matrices A (n, s, s): one vectorized Pade evaluation, the stiff
    modes' (||A_i dt||_1 past NEEDED_NORM, as in the dense path) in double-double."""
    E = expm_stack(A * dt)
    stiff = np.abs(A).sum(axis=1).max(axis=1) * dt > NEEDED_NORM
    if stiff.any():
        E[stiff] = expm_times(A[stiff], dt)
    return E


def solve_modal(model: Model, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, str]:
    """Displacement and velocity (N, n) on the grid, the stated accuracy and a description."""
    n, N = model.n, len(grid)
    shapes, squared, damping = modal_coefficients(model)
    exos = [s.exo() for s in model.signals]
    m = sum(e.S.shape[0] for e in exos)
    size = 2 + m
    A = mode_matrices(squared, damping, size)
    participation = shapes.T @ model.B  # (n, F): how much of force j reaches mode i
    blocks = []  # per signal: its slice of w
    col = 0
    for j, (signal, exo) in enumerate(zip(model.signals, exos)):
        k = exo.S.shape[0]
        A[:, 2 + col:2 + col + k, 2 + col:2 + col + k] = exo.S
        A[:, 1, 2 + col:2 + col + k] = participation[:, j, None] * exo.g[None, :]
        blocks.append((col, col + k, signal))
        col += k
    norms = np.abs(A).sum(axis=1).max(axis=1)  # ||A_i||_1 per mode
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    cache: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def phi(dt: float):
        """(E_yy (n, 2, 2), E_yw (n, 2, m), E_ww (m, m)) over dt."""
        if abs(dt - h) <= 8 * np.spacing(float(grid[-1])):  # the output step, but for the grid times' rounding
            dt = h
        if dt not in cache:
            E = mode_propagators(A, dt)
            cache[dt] = (E[:, :2, :2], E[:, :2, 2:], E[0, 2:, 2:])
        return cache[dt]

    def w_at(t: float) -> np.ndarray:
        w = np.zeros(m)
        for lo, hi, signal in blocks:
            w[lo:hi] = signal.exo_state(t)
        return w

    def step(y: np.ndarray, w: np.ndarray, dt: float) -> np.ndarray:
        Eyy, Eyw, _ = phi(dt)
        return np.einsum("nij,nj->ni", Eyy, y) + Eyw @ w

    y = np.stack([shapes.T @ (model.M @ model.x0), shapes.T @ (model.M @ model.v0)], axis=1)  # (n, 2)
    knots = sampled.uniform_knots(model, grid)
    if knots is not None:  # tables on one even grid (a record): every mode's steps in blocks
        Eyy, Eyw, _ = phi(knots.step)
        segs = len(knots.times) - 1
        forced = (sampled.table_states(blocks, knots.read_at[:-1], 0) @ Eyw.transpose(2, 0, 1).reshape(m, -1)).reshape(
            segs, n, 2)
        states, chain = sampled.recurrence(Eyy, forced, y, knots.rows)
        q, qdot = states[:, :, 0], states[:, :, 1]
        h = knots.step
        chain += segs  # the propagators' own rounding enters every step
        how = f"{plural(segs, 'step')} between the tables' samples and the output points, in blocks"
    else:
        q, qdot = np.empty((N, n)), np.empty((N, n))
        chain = 0
        for t, dt, k in walk(model, grid):  # w reseeded from its closed form at every step: no drift in the forcing
            if dt > 0:
                y = step(y, w_at(t), dt)
                chain += 1
            if k is not None:
                q[k], qdot[k] = y[:, 0], y[:, 1]
        segs = len(segments(model, grid))
        chain += segs
        how = plural(segs, 'force segment')
    x, v = q @ shapes.T, qdot @ shapes.T
    growth = float(norms.max(initial=0.0)) * h
    accurate = growth > NEEDED_NORM
    stated = stated_rounding(chain + n, 1.0 if accurate else growth)
    message = (f"ok: modal coordinates ({n} classically damped modes from a symmetric eigensolver), "
               f"{how}, {len(cache)} batch{'es' if len(cache) != 1 else ''} of {n} exponentials of size {size}"
               + (" (the stiff modes' in double-double)" if accurate else ""))
    return x, v, stated, message
