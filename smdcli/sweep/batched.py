"""Linear members solved together: one batched exact recurrence, y_{k+1} = Phi_yy y_k + Phi_yw w(t_k),
with a vectorized Pade-13 exponential of every member's augmented matrix (expm_stack).

Must not import: io, plots, commands, cli."""

from __future__ import annotations

from typing import Callable

import numpy as np

from smdcli.model import Model
from smdcli.solvers.exact.accurate_expm import expm_stack
from smdcli.sweep.family import Family

# ------------------------------------------------------ batched linear runs


CHUNK = 16384  # members advanced together: long enough vectors that numpy's per-call cost is small
FORCING_BLOCK = 64  # steps whose force terms are made by one matrix product


def shared_signal_recurrence(family: Family, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, Callable[[], np.ndarray]]:
    """Displacement, velocity and acceleration (S, N, n) of a linear family whose members share their forces.

    Each member's state y = [x; v] is augmented with the force generators' state w (shared by all
    members and known in closed form at every grid time), so one output step is exactly
    y_{k+1} = Phi_yy y_k + Phi_yw w(t_k), with [Phi_yy Phi_yw] the top rows of expm(A_aug h).
    A step with a force discontinuity inside is split there. All members advance together, a chunk
    at a time; the arrays are laid out time-major (N, 2n, S) and returned as (S, N, n) views, with a
    function that derives the acceleration when it is wanted (it costs as much as the recurrence).
    """
    from smdcli.solvers.base import segments
    from smdcli.solvers.exact.linear import augmented

    base = family.base
    n, N, S = base.n, len(grid), len(family)
    Aaug0, blocks = augmented(base)
    size = Aaug0.shape[0]
    E = size - 2 * n
    exo_block = Aaug0[2 * n:, 2 * n:]
    g_rows = np.zeros((len(base.signals), E))  # how each signal's generator state makes its value
    for j, (lo, hi, signal) in enumerate(blocks):
        g_rows[j, lo - 2 * n:hi - 2 * n] = signal.exo().g

    def exo_state(t: float) -> np.ndarray:
        return np.concatenate([signal.exo_state(t) for _, _, signal in blocks]) if blocks else np.zeros(0)

    W = np.array([exo_state(t) for t in grid]).reshape(N, E)
    signals = base.forces(grid).reshape(N, len(base.signals))
    split_steps: dict[int, list[float]] = {}
    for tb in [ta for ta, _ in segments(base, grid)][1:]:
        k = int(np.searchsorted(grid, tb, side="right")) - 1
        if grid[k] < tb:
            split_steps.setdefault(k, []).append(tb)
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    uniform = N > 1 and np.allclose(np.diff(grid), h, rtol=1e-9, atol=0)
    Y = np.empty((N, 2 * n, S))  # displacement and velocity
    derivative_rows = []  # per chunk: the acceleration rows of A and M^-1 B
    for lo in range(0, S, CHUNK):
        hi = min(S, lo + CHUNK)
        c = hi - lo
        Minv = np.linalg.inv(family.M[lo:hi])
        A = np.zeros((c, size, size))
        A[:, :n, n:2 * n] = np.eye(n)
        A[:, n:2 * n, :n] = -Minv @ family.K[lo:hi]
        A[:, n:2 * n, n:2 * n] = -Minv @ family.C[lo:hi]
        A[:, 2 * n:, 2 * n:] = exo_block
        force_in = Minv @ base.B  # (c, n, signals)
        if E:
            A[:, n:2 * n, 2 * n:] = force_in @ g_rows
        ys = Y[:, :, lo:hi]
        ys[0, :n], ys[0, n:] = family.x0[lo:hi].T, family.v0[lo:hi].T
        cache: dict[float, np.ndarray] = {}

        def phi(dt: float) -> np.ndarray:
            if dt not in cache:
                cache[dt] = expm_stack(A * dt)
            return cache[dt]

        if uniform:
            step = phi(h)
            # The force's share Phi_yw w(t_k) of each step: one matrix product per block of steps, for every member.
            coupling = np.ascontiguousarray(step[:, :2 * n, 2 * n:].transpose(2, 1, 0)).reshape(E, 2 * n * c)
            forcing = np.zeros((FORCING_BLOCK, 2 * n, c))
            rows = [[np.ascontiguousarray(step[:, i, j]) for j in range(2 * n)] for i in range(2 * n)]
            term = np.empty(c)
        made = -1  # the block of steps whose force terms `forcing` holds
        for k in range(N - 1):
            if uniform and k not in split_steps:
                b = k % FORCING_BLOCK
                if k // FORCING_BLOCK != made and E:  # not only at b == 0: a block's first step may be a split one
                    made = k // FORCING_BLOCK
                    block = W[made * FORCING_BLOCK:(made + 1) * FORCING_BLOCK]
                    np.matmul(block, coupling, out=forcing.reshape(FORCING_BLOCK, -1)[:len(block)])
                now, nxt = ys[k], ys[k + 1]
                for i in range(2 * n):
                    np.multiply(rows[i][0], now[0], out=nxt[i])
                    nxt[i] += forcing[b, i]
                    for j in range(1, 2 * n):
                        np.multiply(rows[i][j], now[j], out=term)
                        nxt[i] += term
                continue
            z = np.concatenate([ys[k].T, np.broadcast_to(W[k], (c, E))], axis=1)
            t_cur = grid[k]
            for tb in split_steps.get(k, []):
                z = np.einsum("sij,sj->si", phi(tb - t_cur), z)
                z[:, 2 * n:] = exo_state(tb)
                t_cur = tb
            ys[k + 1] = np.einsum("sij,sj->si", phi(grid[k + 1] - t_cur), z)[:, :2 * n].T
        derivative_rows.append((lo, hi, A[:, n:2 * n, :2 * n].copy(), force_in))

    def acceleration() -> np.ndarray:
        """a = -M^-1 K x - M^-1 C v + M^-1 B u, component by component over blocks of time and members."""
        out = np.empty((N, n, S))
        for lo, hi, rows_a, force_in in derivative_rows:
            term = np.empty((FORCING_BLOCK, hi - lo))
            for k in range(0, N, FORCING_BLOCK):
                steps = slice(k, min(N, k + FORCING_BLOCK))
                count = steps.stop - k
                for i in range(n):
                    acc = out[steps, i, lo:hi]
                    if len(base.signals):
                        np.matmul(signals[steps], force_in[:, i, :].T, out=term[:count])
                        acc[...] = term[:count]
                    else:
                        acc[...] = 0.0
                    for j in range(2 * n):
                        np.multiply(rows_a[:, i, j], Y[steps, j, lo:hi], out=term[:count])
                        acc += term[:count]
        return np.moveaxis(out, 2, 0)

    return np.moveaxis(Y[:, :n], 2, 0), np.moveaxis(Y[:, n:], 2, 0), acceleration


def batched_exact(models: list[Model], grid: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Displacement and velocity (S, N, n) of linear members with forces of their own (a swept force
    frequency, say) but the same breakpoints: each member's augmented system, one recurrence for all.
    None when the members' force structures or breakpoints differ."""
    from smdcli.solvers.base import segments
    from smdcli.solvers.exact.linear import augmented

    if not all(m.is_linear and all(s.exo() is not None for s in m.signals) for m in models):
        return None
    systems = [augmented(m) for m in models]
    shapes = {(a.shape, tuple((lo, hi) for lo, hi, _ in blocks)) for a, blocks in systems}
    cuts = [segments(m, grid) for m in models]
    if len(shapes) != 1 or any(len(c) != len(cuts[0]) or not np.allclose(c, cuts[0], rtol=0, atol=1e-12)
                               for c in cuts):
        return None
    A = np.stack([a for a, _ in systems])
    S, size = A.shape[0], A.shape[1]
    n, N = models[0].n, len(grid)

    def reseed(z: np.ndarray, t: float) -> None:
        for s, (_, blocks) in enumerate(systems):
            for lo, hi, signal in blocks:
                z[s, lo:hi] = signal.exo_state(t)

    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    phi_h = expm_stack(A * h) if N > 1 else None
    out = np.empty((S, N, 2 * n))
    z = np.zeros((S, size))
    z[:, :n] = [m.x0 for m in models]
    z[:, n:2 * n] = [m.v0 for m in models]
    k = 0
    for index, (ta, tb) in enumerate(cuts[0]):
        last = index == len(cuts[0]) - 1
        reseed(z, ta)
        t_cur = ta
        stop = N if last else int(np.searchsorted(grid, tb, side="left"))
        while k < stop:
            dt = grid[k] - t_cur
            if dt > 0:
                phi = phi_h if abs(dt - h) <= 1e-9 * h else expm_stack(A * dt)
                z = np.einsum("sij,sj->si", phi, z)
            out[:, k] = z[:, :2 * n]
            t_cur = grid[k]
            k += 1
        if not last and tb > t_cur:
            z = np.einsum("sij,sj->si", expm_stack(A * (tb - t_cur)), z)
    return out[:, :, :n], out[:, :, n:]
