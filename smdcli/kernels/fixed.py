"""Compiled fixed-step methods: the generalized-alpha family (Newmark, Hilber-alpha, central difference are cases
of it) on M a + C v + K x + f_nl(x, v) = F(t), and classic Euler and RK4 on the state equation.

Each stretch between cuts (force discontinuities) is cut into equal steps no longer than dt, so a step
never straddles a jump; the method restarts there from equilibrium. Grid rows come from cubic Hermite
interpolation of (x, v) with their slopes (v, a) at the steps, which is as accurate as any of these methods.

The generalized-alpha residual is written divided by M: with g(x, v) = M^-1 (F(t_f) - C v - K x - f_nl),
R(a) = (1 - am) a + am a_n - (1 - af) g(x(a), v(a)) - af g(x_n, v_n), whose force terms cancel, so the
right-hand side kernel serves as it is, and dR/da = (1 - am) I - (1 - af)(beta h^2 J_x + gamma h J_v) comes
from the state Jacobian's lower blocks. A linear model's iteration matrix is factored once per step size;
one solve is then exact.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import OK, STEP_BUDGET, rows_through, state_status
from smdcli.kernels.linalg import lu_factor, lu_solve
from smdcli.kernels.rhs import jacobian, state_rhs

GENERALIZED_ALPHA, EULER, RK4 = range(3)
NEWTON_FAILED = 6  # a status beyond erk's: the implicit step's Newton iteration did not converge
NEWTON_MAXITER = 25
NEWTON_TOL = 1e-10
# Counters (ints): right-hand sides, Jacobians, factorizations, steps.
NFEV, NJEV, NLU, STEPS = range(4)
# Floats: time reached, largest step.
T_REACHED, H_MAX = range(2)


@kernel
def step_count(span, dt):
    """Equal steps no longer than dt that cover span (a hair of rounding does not add a step)."""
    return max(1, math.ceil(span / dt * (1 - 1e-12)))


@no_alloc
def _hermite(t0, h, y0, s0, y1, s1, grid, k, j, out):
    """Rows k..j-1 of out by cubic Hermite interpolation between (y0, s0) at t0 and (y1, s1) at t0 + h."""
    for row in range(k, j):
        s = (grid[row] - t0) / h
        h00 = (1 + 2 * s) * (1 - s) ** 2
        h10 = s * (1 - s) ** 2 * h
        h01 = s * s * (3 - 2 * s)
        h11 = s * s * (s - 1) * h
        for i in range(len(y0)):
            out[row, i] = h00 * y0[i] + h10 * s0[i] + h01 * y1[i] + h11 * s1[i]


@no_alloc
def _iteration_matrix(n, J, am, af, beta, gamma, h, S):
    """S = (1 - am) I - (1 - af)(beta h^2 J_x + gamma h J_v), from the state Jacobian's lower blocks."""
    for r in range(n):
        for q in range(n):
            S[r, q] = -(1 - af) * (beta * h * h * J[n + r, q] + gamma * h * J[n + r, n + q])
        S[r, r] += 1 - am


@no_alloc
def _alpha_step(m, coef, t, h, mid, y, f, y_new, f_new, linear_lu, linear_piv, counts, work, J, S, piv, trial, dy,
                g_n, rest):
    """One generalized-alpha step from y = [x; v] with slope f = [v; a]; True when it succeeded.
    A linear model's iteration matrix comes factored (linear_lu, linear_piv) by the caller for this h."""
    n = m.n
    am, af, beta, gamma = coef[0], coef[1], coef[2], coef[3]
    linear = len(m.el_law) == 0
    tf = t + (1 - af) * h
    left = tf >= mid
    # Newton's increments are judged against |a_n| + |M^-1 F(t_f)|, the size of the accelerations at play.
    scale = 1e-300
    for i in range(n):
        scale = max(scale, abs(f[n + i]))
    if not linear:
        trial[:] = 0.0
        state_rhs(m, tf, trial, left, dy, work, J)  # at rest: M^-1 F(t_f)
        counts[NFEV] += 1
        force_size = 0.0
        for i in range(n):
            force_size = max(force_size, abs(dy[n + i]))
        scale += force_size
    if af != 0.0:
        state_rhs(m, tf, y, left, dy, work, J)
        counts[NFEV] += 1
        for i in range(n):
            g_n[i] = dy[n + i]
    else:
        g_n[:] = 0.0
    for i in range(n):
        rest[i] = am * f[n + i] - af * g_n[i]
    a = f_new[n:]
    for i in range(n):
        a[i] = f[n + i]
    step_size, biggest = 0.0, 0.0
    for _ in range(NEWTON_MAXITER):
        for i in range(n):
            trial[i] = y[i] + h * y[n + i] + h * h * ((0.5 - beta) * f[n + i] + beta * a[i])
            trial[n + i] = y[n + i] + h * ((1 - gamma) * f[n + i] + gamma * a[i])
        state_rhs(m, tf, trial, left, dy, work, J)
        counts[NFEV] += 1
        residual = dy[:n]  # reused as the residual's store: its x-part (= v) is not needed
        for i in range(n):
            residual[i] = (1 - am) * a[i] + rest[i] - (1 - af) * dy[n + i]
        if linear:
            lu_solve(linear_lu, linear_piv, residual)
            for i in range(n):
                a[i] -= residual[i]
        else:
            jacobian(m, trial, J)
            counts[NJEV] += 1
            _iteration_matrix(n, J, am, af, beta, gamma, h, S)
            counts[NLU] += 1
            if not lu_factor(S, piv):
                return False
            lu_solve(S, piv, residual)
            step_size = 0.0
            biggest = 0.0
            for i in range(n):
                a[i] -= residual[i]
                step_size = max(step_size, abs(residual[i]))
                biggest = max(biggest, abs(a[i]))
            if not math.isfinite(step_size):
                return False
        if linear or step_size <= NEWTON_TOL * max(scale, biggest):
            for i in range(n):
                y_new[i] = y[i] + h * y[n + i] + h * h * ((0.5 - beta) * f[n + i] + beta * a[i])
                y_new[n + i] = y[n + i] + h * ((1 - gamma) * f[n + i] + gamma * a[i])
                f_new[i] = y_new[n + i]
            return True
    return False


@no_alloc
def _explicit_step(m, method, t, h, mid, y, f, y_new, f_new, counts, work, J, K, arg):
    """One Euler or RK4 step from y with slope f = f(t, y); f_new = f(t + h, y_new)."""
    size = len(y)
    if method == EULER:
        for i in range(size):
            y_new[i] = y[i] + h * f[i]
    else:
        for s in range(3):
            c = 0.5 if s < 2 else 1.0
            prev = f if s == 0 else K[s - 1]
            for i in range(size):
                arg[i] = y[i] + c * h * prev[i]
            ts = t + c * h
            state_rhs(m, ts, arg, ts >= mid, K[s], work, J)
        counts[NFEV] += 3
        for i in range(size):
            y_new[i] = y[i] + h / 6 * (f[i] + 2 * K[0, i] + 2 * K[1, i] + K[2, i])
    t_new = t + h
    state_rhs(m, t_new, y_new, t_new >= mid, f_new, work, J)
    counts[NFEV] += 1


@kernel
def march(m, method, coef, y0, grid, cuts, dt, max_steps, bound, out, counts, floats, work):
    """Step from y0 = out[0] over the grid with steps no longer than dt, restarting at each cut; a status.

    coef is (alpha_m, alpha_f, beta, gamma) for GENERALIZED_ALPHA. Rows past a failure are NaN."""
    n = m.n
    size = 2 * n
    y, f = y0.copy(), np.zeros(size)
    y_new, f_new = np.zeros(size), np.zeros(size)
    J = np.zeros((size, size))
    S, linear_lu = np.zeros((n, n)), np.zeros((n, n))
    piv, linear_piv = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    K, arg = np.zeros((3, size)), np.zeros(size)
    trial, dy, g_n, rest = np.zeros(size), np.zeros(size), np.zeros(n), np.zeros(n)
    factored_h = -1.0
    k = np.int64(1)  # not a literal 1: the row writers (_dense, _hermite) compile once, for any row
    total = 0
    floats[T_REACHED] = grid[0]
    for seg in range(len(cuts) - 1):
        ta, tb = cuts[seg], cuts[seg + 1]
        mid = 0.5 * (ta + tb)
        steps = step_count(tb - ta, dt)
        h = (tb - ta) / steps
        floats[H_MAX] = max(floats[H_MAX], h)
        state_rhs(m, ta, y, np.bool_(False), f, work, J)  # restart from equilibrium
        counts[NFEV] += 1
        if method == GENERALIZED_ALPHA and len(m.el_law) == 0 and h != factored_h:
            jacobian(m, y, J)
            _iteration_matrix(n, J, coef[0], coef[1], coef[2], coef[3], h, linear_lu)
            if not lu_factor(linear_lu, linear_piv):
                out[k:] = np.nan
                return NEWTON_FAILED
            counts[NLU] += 1
            factored_h = h
        t = ta
        for i in range(steps):
            if total >= max_steps:
                out[k:] = np.nan
                return STEP_BUDGET
            t_new = tb if i == steps - 1 else ta + (i + 1) * h
            if method == GENERALIZED_ALPHA:
                if not _alpha_step(m, coef, t, h, mid, y, f, y_new, f_new, linear_lu, linear_piv, counts, work, J, S,
                                   piv, trial, dy, g_n, rest):
                    out[k:] = np.nan
                    return NEWTON_FAILED
            else:
                _explicit_step(m, method, t, h, mid, y, f, y_new, f_new, counts, work, J, K, arg)
            total += 1
            counts[STEPS] = total
            status = state_status(y_new, bound)
            if status != OK:
                out[k:] = np.nan
                return status
            j = rows_through(grid, k, t_new)
            if j > k:
                _hermite(t, t_new - t, y, f, y_new, f_new, grid, k, j, out)
                k = j
            floats[T_REACHED] = t_new
            t = t_new
            y[:] = y_new
            f[:] = f_new
    return OK
