"""Compiled Newmark average acceleration on banded symmetric matrices: a sparse scene reordered to a narrow band
(reverse Cuthill-McKee), its effective stiffness K + 2 C / h + 4 M / h^2 factored once per step size by banded
Cholesky, every step then O(n w) for a band of half-width w (a chain's is 1).

A band is held in LAPACK's lower form: band[d, j] = A[j + d, j], d = 0..w. Cubic springs and quadratic dampers
(few, two-terminal) enter each step by modified Newton on the linear factor, refactored at the tangent where it
contracts slowly, as smdcli.solvers.integrators.sparse_newmark does in Python.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.compiler import kernel

OK, NOT_DEFINITE, NEWTON_FAILED = range(3)
NEWTON_ITERATIONS = 40
NEWTON_SLOW = 0.25
NEWTON_TOL = 1e-13  # of the state's size: far below what the extrapolation keeps
# Counters: steps, force evaluations, tangent factorizations; and the time a failure happened.
STEPS, EVALUATIONS, TANGENTS = range(3)


@kernel
def cholesky(band) -> bool:
    """Factor a symmetric positive definite band in place (lower, L L^T), its diagonal held as reciprocals (a
    substitution's chain of dependent rows then multiplies instead of dividing); False where it is not definite."""
    w = band.shape[0] - 1
    n = band.shape[1]
    for j in range(n):
        s = band[0, j]
        for k in range(max(0, j - w), j):
            s -= band[j - k, k] * band[j - k, k]
        if not s > 0.0:
            return False
        reciprocal = 1.0 / math.sqrt(s)
        band[0, j] = reciprocal
        for i in range(j + 1, min(n, j + w + 1)):
            s = band[i - j, j]
            for k in range(max(0, i - w), j):
                s -= band[i - k, k] * band[j - k, k]
            band[i - j, j] = s * reciprocal
    return True


@kernel
def solve(factor, b) -> None:
    """b <- A^-1 b from A's banded Cholesky factor (cholesky's)."""
    w = factor.shape[0] - 1
    n = factor.shape[1]
    if w == 1:  # a chain's: the last value carried in a register, not stored and loaded back (twice as fast)
        last = b[0] * factor[0, 0]
        b[0] = last
        for i in range(1, n):
            last = (b[i] - factor[1, i - 1] * last) * factor[0, i]
            b[i] = last
        last = b[n - 1] * factor[0, n - 1]
        b[n - 1] = last
        for i in range(n - 2, -1, -1):
            last = (b[i] - factor[1, i] * last) * factor[0, i]
            b[i] = last
        return
    for i in range(n):
        s = b[i]
        for k in range(max(0, i - w), i):
            s -= factor[i - k, k] * b[k]
        b[i] = s * factor[0, i]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, min(n, i + w + 1)):
            s -= factor[k - i, i] * b[k]
        b[i] = s * factor[0, i]


@kernel
def add_times(band, x, out) -> None:
    """out += A x for a symmetric band A."""
    w = band.shape[0] - 1
    n = band.shape[1]
    if w == 1:
        out[0] += band[0, 0] * x[0] + (band[1, 0] * x[1] if n > 1 else 0.0)
        for j in range(1, n - 1):
            out[j] += band[1, j - 1] * x[j - 1] + band[0, j] * x[j] + band[1, j] * x[j + 1]
        if n > 1:
            out[n - 1] += band[1, n - 2] * x[n - 2] + band[0, n - 1] * x[n - 1]
        return
    for j in range(n):
        out[j] += band[0, j] * x[j]
        for d in range(1, min(w, n - 1 - j) + 1):
            out[j + d] += band[d, j] * x[j]
            out[j] += band[d, j] * x[j + d]


@kernel
def _nonlinear(cubic, cubic_coef, quadratic, quadratic_coef, x, v, out) -> None:
    """out += f_nl(x, v): cubic springs k3 d^3 and quadratic dampers c |d'| d' between node pairs (-1: ground)."""
    for e in range(cubic.shape[0]):
        a, b = cubic[e, 0], cubic[e, 1]
        d = (x[a] if a >= 0 else 0.0) - (x[b] if b >= 0 else 0.0)
        f = cubic_coef[e] * d * d * d
        if a >= 0:
            out[a] += f
        if b >= 0:
            out[b] -= f
    for e in range(quadratic.shape[0]):
        a, b = quadratic[e, 0], quadratic[e, 1]
        d = (v[a] if a >= 0 else 0.0) - (v[b] if b >= 0 else 0.0)
        f = quadratic_coef[e] * abs(d) * d
        if a >= 0:
            out[a] += f
        if b >= 0:
            out[b] -= f


@kernel
def _stamp(band, a, b, value) -> None:
    """A two-terminal element's tangent value into a band: [[v, -v], [-v, v]] on (a, b)."""
    if a >= 0:
        band[0, a] += value
    if b >= 0:
        band[0, b] += value
    if a >= 0 and b >= 0:
        band[abs(a - b), min(a, b)] -= value


@kernel
def _equilibrium(mass, damping, stiffness, forcing, u, cubic, cubic_coef, quadratic, quadratic_coef, x, v, kx, cv,
                 a) -> None:
    """kx = K x, cv = C v, and a = M^-1 (F(u) - C v - K x - f_nl(x, v)) (M diagonal)."""
    n = x.shape[0]
    for j in range(n):
        kx[j] = 0.0
        cv[j] = 0.0
        a[j] = 0.0
    add_times(stiffness, x, kx)
    add_times(damping, v, cv)
    _nonlinear(cubic, cubic_coef, quadratic, quadratic_coef, x, v, a)  # f_nl, held in a for a moment
    for j in range(n):
        force = 0.0
        for q in range(forcing.shape[1]):
            force += forcing[j, q] * u[q]
        a[j] = (force - kx[j] - cv[j] - a[j]) / mass[0, j]


@kernel
def march(mass, damping, stiffness, effective, factors, steps, factor_of, divisions, ends, restart, u_start, u_steps,
          forcing, cubic, cubic_coef, quadratic, quadratic_coef, order, slot, x, v, x_out, v_out, counts,
          failed_at) -> int:
    """One Newmark run over intervals between nodes, each cut into `divisions` equal steps.

    mass (1, n: diagonal), damping, stiffness: bands (w+1, n) in the reordered numbering; effective and factors:
    per step size steps[f], K + 2 C / h + 4 M / h^2 and its Cholesky factor; factor_of[i]: interval i's; ends[i],
    ends[i + 1]: its times; restart[i]: the acceleration starts from equilibrium there (the start, a force's
    jump); u_start[i]: the forces there, u_steps[i, k]: at the end of its step k (left limits at a jump); forcing
    (n, signals): where each signal acts. order[i]: the scene's DOF at reordered position i; slot[i]: the output
    row of node i (-1: a node that is not an output point). x and v: the start state, reordered, marched in place.

    Each step solves for the increment d = x1 - x0, K_eff d = F1 - K x0 + C v0 + M (4 v0 / h + a0), and takes the
    acceleration from equilibrium at its end: the total form (K_eff x1 = F1 + M (4 x0 / h^2 + ...)) carries
    x0 / h^2 through every step, and its rounding, 4 eps |x| / h^2 in a, grew to 1e-8 of the peak at fine steps."""
    n = x.shape[0]
    a = np.zeros(n)
    kx = np.zeros(n)
    cv = np.zeros(n)
    rhs = np.zeros(n)
    d = np.zeros(n)
    tangent = np.empty_like(factors[0])
    nonlinear = cubic.shape[0] + quadratic.shape[0] > 0
    chain = not nonlinear and factors.shape[1] == 2 and n > 2  # a linear chain: stepped by _chain_step
    intervals = ends.shape[0] - 1
    for i in range(intervals + 1):
        if slot[i] >= 0:
            for j in range(n):
                x_out[slot[i], order[j]] = x[j]
                v_out[slot[i], order[j]] = v[j]
        if i == intervals:
            break
        if restart[i]:
            _equilibrium(mass, damping, stiffness, forcing, u_start[i], cubic, cubic_coef, quadratic,
                         quadratic_coef, x, v, kx, cv, a)
            counts[EVALUATIONS] += 1
        f = factor_of[i]
        h = steps[f]
        c2, c3 = 2.0 / h, 4.0 / h
        for k in range(divisions):
            if chain:
                _chain_step(mass, damping, stiffness, factors[f], forcing, u_steps[i, k], c2, c3, x, v, a, kx, cv,
                            d, rhs)
                counts[STEPS] += 1
                continue
            for j in range(n):
                s = 0.0
                for q in range(forcing.shape[1]):
                    s += forcing[j, q] * u_steps[i, k, q]
                rhs[j] = s - kx[j] + cv[j] + mass[0, j] * (c3 * v[j] + a[j])
                d[j] = rhs[j]
            solve(factors[f], d)  # the increment, linear part
            if nonlinear:
                status = _newton(effective[f], factors[f], tangent, cubic, cubic_coef, quadratic, quadratic_coef,
                                 x, v, rhs, d, c2, counts)
                if status != OK:
                    failed_at[0] = ends[i] + (k + 1) * h
                    return status
            for j in range(n):
                x[j] += d[j]
                v[j] = c2 * d[j] - v[j]
            _equilibrium(mass, damping, stiffness, forcing, u_steps[i, k], cubic, cubic_coef, quadratic,
                         quadratic_coef, x, v, kx, cv, a)
            counts[STEPS] += 1
    return OK


@kernel
def _chain_step(mass, damping, stiffness, factor, forcing, u, c2, c3, x, v, a, kx, cv, y, f) -> None:
    """One linear step of a chain (half-bandwidth 1, n > 2) in two passes over it, not seven: the right-hand side
    F1 - K x0 + C v0 + M (4 v0 / h + a0) of each row built as the forward substitution reaches it, and each row's x
    and v, and once its neighbours are new its K x, C v and acceleration, updated in the backward one. The same
    arithmetic as march's general path, in its order: the same results to the bit, in three quarters of the time.
    (Written out, not in helpers: an inlined helper's array arguments are reference-counted at every row.)"""
    n = x.shape[0]
    last = 0.0
    for i in range(n):
        force = 0.0
        for q in range(forcing.shape[1]):
            force += forcing[i, q] * u[q]
        f[i] = force
        rhs = force - kx[i] + cv[i] + mass[0, i] * (c3 * v[i] + a[i])
        last = rhs * factor[0, 0] if i == 0 else (rhs - factor[1, i - 1] * last) * factor[0, i]
        y[i] = last
    last = y[n - 1] * factor[0, n - 1]
    x[n - 1] += last
    v[n - 1] = c2 * last - v[n - 1]
    for i in range(n - 2, -1, -1):
        last = (y[i] - factor[1, i] * last) * factor[0, i]
        x[i] += last
        v[i] = c2 * last - v[i]
        j = i + 1  # x and v are new on i .. n - 1
        if j == n - 1:
            kx[j] = 0.0 + (stiffness[1, j - 1] * x[j - 1] + stiffness[0, j] * x[j])
            cv[j] = 0.0 + (damping[1, j - 1] * v[j - 1] + damping[0, j] * v[j])
        else:
            kx[j] = 0.0 + (stiffness[1, j - 1] * x[j - 1] + stiffness[0, j] * x[j] + stiffness[1, j] * x[j + 1])
            cv[j] = 0.0 + (damping[1, j - 1] * v[j - 1] + damping[0, j] * v[j] + damping[1, j] * v[j + 1])
        a[j] = (f[j] - kx[j] - cv[j] - 0.0) / mass[0, j]
    kx[0] = 0.0 + (stiffness[0, 0] * x[0] + stiffness[1, 0] * x[1])
    cv[0] = 0.0 + (damping[0, 0] * v[0] + damping[1, 0] * v[1])
    a[0] = (f[0] - kx[0] - cv[0] - 0.0) / mass[0, 0]


@kernel
def _newton(effective, factor, tangent, cubic, cubic_coef, quadratic, quadratic_coef, x, v, rhs, d, c2,
            counts) -> int:
    """d <- the root of K_eff d + f_nl(x + d, c2 d - v) = rhs, from d: modified Newton on the linear factor,
    switched to the tangent's, refactored, wherever it contracts slowly."""
    n = x.shape[0]
    position = np.empty(n)
    velocity = np.empty(n)
    residual = np.empty(n)
    scale = 1e-300
    for j in range(n):
        scale = max(scale, abs(d[j]) + abs(x[j]))
    previous = np.inf
    on_tangent = False
    for _ in range(NEWTON_ITERATIONS):
        for j in range(n):
            position[j] = x[j] + d[j]
            velocity[j] = c2 * d[j] - v[j]
            residual[j] = 0.0
        add_times(effective, d, residual)
        _nonlinear(cubic, cubic_coef, quadratic, quadratic_coef, position, velocity, residual)
        counts[EVALUATIONS] += 1
        for j in range(n):
            residual[j] = rhs[j] - residual[j]
        solve(tangent if on_tangent else factor, residual)
        size = 0.0
        for j in range(n):
            d[j] += residual[j]
            size = max(size, abs(residual[j]))
        if size <= NEWTON_TOL * scale:
            return OK
        if size > NEWTON_SLOW * previous:  # slow: Newton proper, on the tangent here (again while it stays slow)
            tangent[:, :] = effective
            for e in range(cubic.shape[0]):
                a, b = cubic[e, 0], cubic[e, 1]
                gap = (x[a] + d[a] if a >= 0 else 0.0) - (x[b] + d[b] if b >= 0 else 0.0)
                _stamp(tangent, a, b, 3.0 * cubic_coef[e] * gap * gap)
            for e in range(quadratic.shape[0]):
                a, b = quadratic[e, 0], quadratic[e, 1]
                rate = (c2 * d[a] - v[a] if a >= 0 else 0.0) - (c2 * d[b] - v[b] if b >= 0 else 0.0)
                _stamp(tangent, a, b, 2.0 * quadratic_coef[e] * abs(rate) * c2)
            if not cholesky(tangent):
                return NOT_DEFINITE
            on_tangent = True
            counts[TANGENTS] += 1
        previous = size
    return NEWTON_FAILED
