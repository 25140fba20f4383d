"""Variable-order NDF/BDF (orders 1-5) compiled, with the model's analytic Jacobian: scipy.integrate.BDF's method
step for step (Shampine and Reichelt's quasi-constant step NDF of "The MATLAB ODE Suite", as behind ode15s:
a backward-difference array rescaled when the step changes, simplified Newton with a reused iteration matrix,
order raised or lowered from the neighbouring orders' error estimates, and the difference polynomial as dense
output). The scipy-driven `scipy:BDF` stays as the cross-check.

The integration restarts at every cut (force discontinuity), as a new scipy solver would.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import OK, STEP_BUDGET, TOO_SMALL_STEP, initial_step, scaled_rms, state_status
from smdcli.kernels.guards import BDF, stop_at, watch_scratch, watch_step
from smdcli.kernels.linalg import factor_shifted, lu_solve
from smdcli.kernels.radau import (ACCEPTED, EPS, NFEV, NJEV, NLU, REJECTED, T_REACHED,  # the same statistics
                                  newton_hopeless, newton_settled, newton_tolerance)
from smdcli.kernels.rhs import state_jacobian, state_rhs

MAX_ORDER = 5
NEWTON_MAXITER = 4
MIN_FACTOR, MAX_FACTOR = 0.2, 10.0
KAPPA = np.array([0, -0.1850, -1 / 9, -0.0823, -0.0415, 0])
GAMMA = np.concatenate((np.zeros(1), np.cumsum(1 / np.arange(1, MAX_ORDER + 1))))
ALPHA = (1 - KAPPA) * GAMMA
ERROR_CONST = KAPPA * GAMMA + 1 / np.arange(1, MAX_ORDER + 2)


@no_alloc
def _compute_r(order, factor, R):
    """scipy's compute_R into R[:order + 1, :order + 1]: the matrix that rescales the difference array."""
    for q in range(order + 1):
        R[0, q] = 1.0
    for i in range(1, order + 1):
        for q in range(order + 1):
            R[i, q] = R[i - 1, q] * ((i - 1 - factor * q) / i if q > 0 else 0.0)
    # Column 0 below row 0 is zero in scipy's M, so its cumulative product is zero there too.


@no_alloc
def change_d(D, order, factor, R, U, RU, scratch):
    """Rescale the difference array in place for a step changed by `factor` (scipy's change_D)."""
    _compute_r(order, factor, R)
    _compute_r(order, 1.0, U)
    for i in range(order + 1):
        for q in range(order + 1):
            s = 0.0
            for k in range(order + 1):
                s += R[i, k] * U[k, q]
            RU[i, q] = s
    size = D.shape[1]
    for q in range(order + 1):
        for c in range(size):
            s = 0.0
            for i in range(order + 1):
                s += RU[i, q] * D[i, c]
            scratch[q, c] = s
    for q in range(order + 1):
        for c in range(size):
            D[q, c] = scratch[q, c]


@no_alloc
def _newton(m, t_new, y_predict, c, psi, LU, piv, scale, tol, mid, y, d, dy, f, work, Jscratch, counts, out):
    """scipy's solve_bdf_system: y and d from the prediction; out[0] = iterations, out[1] = rate. True if converged."""
    size = len(y)
    for i in range(size):
        y[i] = y_predict[i]
        d[i] = 0.0
    old = -1.0
    rate = -1.0
    converged = False
    k = 0
    for k in range(NEWTON_MAXITER):
        state_rhs(m, t_new, y, t_new >= mid, f, work, Jscratch)
        counts[NFEV] += 1
        finite = True
        for i in range(size):
            if not math.isfinite(f[i]):
                finite = False
        if not finite:
            break
        for i in range(size):
            dy[i] = c * f[i] - psi[i] - d[i]
        lu_solve(LU, piv, dy)
        norm = scaled_rms(dy, scale)
        rate = norm / old if old >= 0 else -1.0
        if newton_hopeless(rate, norm, NEWTON_MAXITER - k, tol):
            break
        for i in range(size):
            y[i] += dy[i]
            d[i] += dy[i]
        if newton_settled(rate, norm, tol):
            converged = True
            break
        old = norm
    out[0] = k + 1
    out[1] = rate
    return converged


@kernel
def integrate(m, y0, grid, cuts, rtol, atol, max_steps, bound, out, counts, floats, work, fixed_h):
    """Integrate from y0 = out[0] over the grid with variable-order NDF, restarting at each cut; a status (erk's
    codes). counts and floats receive radau's statistics; work is the right-hand side's scratch. fixed_h is not
    supported (the order varies) and must be 0."""
    y = y0.copy()
    none = np.zeros((0, 0))
    # int64 arguments, not literal ints: the overload the modes' runs compile and load, not a second one
    zero, one, no_guard = np.int64(0), np.int64(1), np.int64(-1)
    status, k, _ = integrate_mode(m, zero, y, grid[0], cuts[1:], 0.5 * (cuts[:-1] + cuts[1:]), grid, one, rtol, atol,
                                  max_steps, bound, -np.inf, no_guard, out, none, none, counts, floats, work, 0.0)
    if status != OK:
        out[k:] = np.nan
    return status


@kernel
def integrate_mode(m, method, y, t0, bounds, mids, grid, k, rtol, atol, max_steps, bound, skip_t, skip_guard, out,
                   out_a, out_t, counts, floats, work, fixed_h):
    """events.integrate_mode with variable-order NDF (method and fixed_h are unused): from (t0, y) through the
    stretches ending at bounds (restarting at each), rows written from k, the mode's guards (if any) watched on the
    difference polynomial: (status, next row, guard fired or -1); y ends where it stopped."""
    floats[T_REACHED] = t0
    size = len(y)
    rtol = max(rtol, 100 * EPS)
    newton_tol = newton_tolerance(rtol)
    J, Jscratch, LU = np.zeros((size, size)), np.zeros((1, 1)), np.zeros((size, size))
    piv = np.zeros(size, dtype=np.int64)
    D, scratch = np.zeros((MAX_ORDER + 3, size)), np.zeros((MAX_ORDER + 3, size))
    R, U, RU = np.zeros((MAX_ORDER + 1, MAX_ORDER + 1)), np.zeros((MAX_ORDER + 1, MAX_ORDER + 1)), \
        np.zeros((MAX_ORDER + 1, MAX_ORDER + 1))
    f, y_new, d = np.zeros(size), np.zeros(size), np.zeros(size)
    y_predict, psi, dy, scale, arg = np.zeros(size), np.zeros(size), np.zeros(size), np.zeros(size), np.zeros(size)
    y_old, f1 = np.zeros(size), np.zeros(size)
    newton = np.zeros(2)
    factors = np.zeros(3)
    samples, rows, values, when, row = watch_scratch(m, size)
    dense, Q = np.zeros((1, 3)), np.zeros((1, 1))
    t = t0
    for stretch in range(len(bounds)):
        t_bound, mid = bounds[stretch], mids[stretch]
        if t >= t_bound:
            continue
        state_rhs(m, t, y, t >= mid, f, work, Jscratch)
        counts[NFEV] += 1
        self_h_abs = initial_step(m, t, y, f, t_bound, np.int64(1), rtol, atol, mid, work, Jscratch, arg, y_new, scale)
        counts[NFEV] += 1
        counts[NFEV] += state_jacobian(m, t, y, mid, rtol, atol, J, work, Jscratch, dy, arg, f1)
        counts[NJEV] += 1
        D[:, :] = 0.0
        for i in range(size):
            D[0, i] = y[i]
            D[1, i] = f[i] * self_h_abs
        order = np.int64(1)  # not a literal 1: change_d's one compile, not a second for order 1
        n_equal_steps = 0
        factored = False
        while t < t_bound:
            min_step = 10 * abs(np.nextafter(t, np.inf) - t)
            if self_h_abs < min_step:
                h_abs = min_step
                change_d(D, order, min_step / self_h_abs, R, U, RU, scratch)
                n_equal_steps = 0
            else:
                h_abs = self_h_abs
            current_jac = False
            safety = 0.0
            error_norm = 0.0
            while True:
                if h_abs < min_step:
                    floats[T_REACHED] = t
                    return TOO_SMALL_STEP, k, -1
                t_new = t + h_abs
                if t_new > t_bound:
                    t_new = t_bound
                    change_d(D, order, abs(t_new - t) / h_abs, R, U, RU, scratch)
                    n_equal_steps = 0
                    factored = False
                h = t_new - t
                h_abs = abs(h)
                for i in range(size):
                    s = 0.0
                    for q in range(order + 1):
                        s += D[q, i]
                    y_predict[i] = s
                    scale[i] = atol[i] + rtol * abs(s)
                    p = 0.0
                    for q in range(1, order + 1):
                        p += D[q, i] * GAMMA[q]
                    psi[i] = p / ALPHA[order]
                c = h / ALPHA[order]
                converged = False
                while True:
                    if not factored:
                        counts[NLU] += 1
                        if not factor_shifted(J, 1.0, c, LU, piv):
                            break
                        factored = True
                    converged = _newton(m, t_new, y_predict, c, psi, LU, piv, scale, newton_tol, mid, y_new, d, dy,
                                        arg, work, Jscratch, counts, newton)
                    if converged or current_jac:
                        break
                    counts[NFEV] += state_jacobian(m, t_new, y_predict, mid, rtol, atol, J, work, Jscratch, dy, arg,
                                                   f1)
                    counts[NJEV] += 1
                    factored = False
                    current_jac = True
                if not converged:
                    h_abs *= 0.5
                    change_d(D, order, 0.5, R, U, RU, scratch)
                    n_equal_steps = 0
                    factored = False
                    counts[REJECTED] += 1
                    continue
                safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + newton[0])
                for i in range(size):
                    scale[i] = atol[i] + rtol * abs(y_new[i])
                    dy[i] = ERROR_CONST[order] * d[i]
                error_norm = scaled_rms(dy, scale)
                if error_norm > 1:
                    factor = max(MIN_FACTOR, safety * error_norm ** (-1.0 / (order + 1)))
                    h_abs *= factor
                    change_d(D, order, factor, R, U, RU, scratch)
                    n_equal_steps = 0
                    counts[REJECTED] += 1
                else:
                    break
            counts[ACCEPTED] += 1
            if counts[ACCEPTED] > max_steps:
                return STEP_BUDGET, k, -1
            n_equal_steps += 1
            t_old = t
            y_old[:] = y
            t = t_new
            y[:] = y_new
            self_h_abs = h_abs
            for i in range(size):
                D[order + 2, i] = d[i] - D[order + 1, i]
                D[order + 1, i] = d[i]
            for q in range(order, -1, -1):
                for i in range(size):
                    D[q, i] += D[q + 1, i]
            if n_equal_steps >= order + 1:
                if order > 1:
                    for i in range(size):
                        dy[i] = ERROR_CONST[order - 1] * D[order, i]
                    error_m_norm = scaled_rms(dy, scale)
                else:
                    error_m_norm = math.inf
                if order < MAX_ORDER:
                    for i in range(size):
                        dy[i] = ERROR_CONST[order + 1] * D[order + 2, i]
                    error_p_norm = scaled_rms(dy, scale)
                else:
                    error_p_norm = math.inf
                factors[0] = error_m_norm ** (-1.0 / order) if error_m_norm > 0 else math.inf
                factors[1] = error_norm ** (-1.0 / (order + 1)) if error_norm > 0 else math.inf
                factors[2] = error_p_norm ** (-1.0 / (order + 2)) if error_p_norm > 0 else math.inf
                best = 0
                for q in range(1, 3):
                    if factors[q] > factors[best]:
                        best = q
                order += best - 1
                factor = min(MAX_FACTOR, safety * factors[best])
                self_h_abs *= factor
                change_d(D, order, factor, R, U, RU, scratch)
                n_equal_steps = 0
                factored = False
            # Dense output: the difference polynomial at the step's end, in units of the next step (scipy's).
            dense[0, 0], dense[0, 1], dense[0, 2] = t, self_h_abs, order
            k, t_stop, fired = watch_step(m, np.int64(BDF), t_old, t, t - t_old, y_old, y, D, dense, Q, grid, k, mid,
                                          work, Jscratch, arg, skip_t, skip_guard, samples, rows, values, when, row, dy,
                                          out, out_a, out_t)
            if fired >= 0:
                return stop_at(m, y, row, t_stop, bound, floats), k, fired
            floats[T_REACHED] = t
            status = state_status(y, bound)
            if status != OK:
                return status, k, -1
            if t_old == t:  # no progress is possible: a step below rounding
                floats[T_REACHED] = t
                return TOO_SMALL_STEP, k, -1
    return OK, k, -1
