"""Radau IIA of order 5 compiled, with the model's analytic Jacobian: scipy.integrate.Radau's method step
for step (Hairer and Wanner's RADAU5 as scipy writes it: the collocation system solved by simplified Newton
in the eigenbasis of the method's matrix, one real and one complex factorization per step size, the
embedded error estimate with its extra correction after a rejection, the predictive step controller and the
collocation polynomial as dense output). The scipy-driven `scipy:Radau` stays as the cross-check.

The integration restarts at every cut (force discontinuity), as a new scipy solver would.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import OK, STEP_BUDGET, TOO_SMALL_STEP, initial_step, state_status
from smdcli.kernels.guards import RADAU, stop_at, watch_scratch, watch_step
from smdcli.kernels.linalg import factor_shifted, lu_solve
from smdcli.kernels.rhs import state_jacobian, state_rhs

# Counters (ints): right-hand sides, accepted, rejected, Jacobians, factorizations.
NFEV, ACCEPTED, REJECTED, NJEV, NLU = range(5)
T_REACHED = 0  # floats: time reached

EPS = np.finfo(np.float64).eps
S6 = 6**0.5
C = np.array([(4 - S6) / 10, (4 + S6) / 10, 1.0])
E = np.array([-13 - 7 * S6, -13 + 7 * S6, -1.0]) / 3
MU_REAL = 3 + 3 ** (2 / 3) - 3 ** (1 / 3)
MU_COMPLEX = 3 + 0.5 * (3 ** (1 / 3) - 3 ** (2 / 3)) - 0.5j * (3 ** (5 / 6) + 3 ** (7 / 6))
T = np.array([
    [0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
    [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
    [1.0, 1.0, 0.0]])
TI = np.array([
    [4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
    [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
    [0.50287263494578682, -2.57192694985560522, 0.59603920482822492]])
P = np.array([
    [13 / 3 + 7 * S6 / 3, -23 / 3 - 22 * S6 / 3, 10 / 3 + 5 * S6],
    [13 / 3 - 7 * S6 / 3, -23 / 3 + 22 * S6 / 3, 10 / 3 - 5 * S6],
    [1 / 3, -8 / 3, 10 / 3]])
NEWTON_MAXITER = 6
MIN_FACTOR, MAX_FACTOR = 0.2, 10.0


@no_alloc
def _rms_scaled(x, scale):
    """scipy's norm(x / scale) over every entry of a (rows, n) array."""
    total = 0.0
    rows, n = x.shape
    for r in range(rows):
        for i in range(n):
            q = x[r, i] / scale[i]
            total += q * q
    return math.sqrt(total / (rows * n))


@no_alloc
def _collocation(m, t, y, h, Z0, scale, tol, LU_real, LU_complex, piv_real, piv_complex, mid, Z, W, dW, F, arg,
                 b_real, b_complex, work, Jscratch, counts, out):
    """scipy's solve_collocation_system: Z from the guess Z0; out[0] = iterations, out[1] = rate (-1: none).
    True when converged."""
    size = len(y)
    for r in range(3):
        for i in range(size):
            W[r, i] = TI[r, 0] * Z0[0, i] + TI[r, 1] * Z0[1, i] + TI[r, 2] * Z0[2, i]
            Z[r, i] = Z0[r, i]
    old = -1.0
    rate = -1.0
    converged = False
    k = 0
    for k in range(NEWTON_MAXITER):
        finite = True
        for r in range(3):
            for i in range(size):
                arg[i] = y[i] + Z[r, i]
            ts = t + h * C[r]
            state_rhs(m, ts, arg, ts >= mid, F[r], work, Jscratch)
            counts[NFEV] += 1
            for i in range(size):
                if not math.isfinite(F[r, i]):
                    finite = False
        if not finite:
            break
        for i in range(size):
            b_real[i] = TI[0, 0] * F[0, i] + TI[0, 1] * F[1, i] + TI[0, 2] * F[2, i] - MU_REAL / h * W[0, i]
            b_complex[i] = (complex(TI[1, 0] * F[0, i] + TI[1, 1] * F[1, i] + TI[1, 2] * F[2, i],
                                    TI[2, 0] * F[0, i] + TI[2, 1] * F[1, i] + TI[2, 2] * F[2, i])
                            - MU_COMPLEX / h * complex(W[1, i], W[2, i]))
        lu_solve(LU_real, piv_real, b_real)
        lu_solve(LU_complex, piv_complex, b_complex)
        for i in range(size):
            dW[0, i] = b_real[i]
            dW[1, i] = b_complex[i].real
            dW[2, i] = b_complex[i].imag
        norm = _rms_scaled(dW, scale)
        if old >= 0:
            rate = norm / old
        if newton_hopeless(rate, norm, NEWTON_MAXITER - k, tol):
            break
        for r in range(3):
            for i in range(size):
                W[r, i] += dW[r, i]
        for r in range(3):
            for i in range(size):
                Z[r, i] = T[r, 0] * W[0, i] + T[r, 1] * W[1, i] + T[r, 2] * W[2, i]
        if newton_settled(rate, norm, tol):
            converged = True
            break
        old = norm
    out[0] = k + 1
    out[1] = rate
    return converged


@no_alloc
def newton_tolerance(rtol):
    """scipy's stopping tolerance of the Newton iteration, relative to the error scale."""
    return max(10 * EPS / rtol, min(0.03, rtol**0.5))


@no_alloc
def newton_hopeless(rate, norm, left, tol):
    """scipy's verdict on a simplified Newton iteration with `left` iterations to go: diverging (rate >= 1), or
    too slow to reach tol in time; rate < 0 means none measured yet."""
    return rate >= 0 and (rate >= 1 or rate**left / (1 - rate) * norm > tol)


@no_alloc
def newton_settled(rate, norm, tol):
    """scipy's convergence test: the increment vanished, or the remaining error rate / (1 - rate) * norm < tol."""
    return norm == 0 or (rate >= 0 and rate / (1 - rate) * norm < tol)


@no_alloc
def _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old):
    """scipy's predictive step-size factor (Gustafsson's controller); h_abs_old < 0 means none."""
    if error_norm_old < 0 or h_abs_old < 0 or error_norm == 0:
        multiplier = 1.0
    else:
        multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** 0.25
    if error_norm == 0:
        return math.inf
    return min(1.0, multiplier) * error_norm ** -0.25


@kernel
def integrate(m, y0, grid, cuts, rtol, atol, max_steps, bound, out, counts, floats, work, fixed_h):
    """Integrate from y0 = out[0] over the grid with Radau IIA 5, restarting at each cut; a status (erk's codes).
    counts and floats receive the statistics named above; work is the right-hand side's scratch. fixed_h > 0
    takes steps of that size with no error control (for measuring the formula's order)."""
    y = y0.copy()
    none = np.zeros((0, 0))
    # int64 arguments, not literal ints: the overload the modes' runs compile and load, not a second one
    zero, one, no_guard = np.int64(0), np.int64(1), np.int64(-1)
    status, k, _ = integrate_mode(m, zero, y, grid[0], cuts[1:], 0.5 * (cuts[:-1] + cuts[1:]), grid, one, rtol, atol,
                                  max_steps, bound, -np.inf, no_guard, out, none, none, counts, floats, work, fixed_h)
    if status != OK:
        out[k:] = np.nan
    return status


@kernel
def integrate_mode(m, method, y, t0, bounds, mids, grid, k, rtol, atol, max_steps, bound, skip_t, skip_guard, out,
                   out_a, out_t, counts, floats, work, fixed_h):
    """events.integrate_mode with Radau IIA 5 (method is unused): from (t0, y) through the stretches ending at
    bounds (restarting at each), rows written from k, the mode's guards (if any) watched on the collocation
    polynomial: (status, next row, guard fired or -1); y ends where it stopped."""
    floats[T_REACHED] = t0
    size = len(y)
    rtol = max(rtol, 100 * EPS)
    newton_tol = newton_tolerance(rtol)
    J, Jscratch = np.zeros((size, size)), np.zeros((1, 1))
    LU_real = np.zeros((size, size))
    LU_complex = np.zeros((size, size), dtype=np.complex128)
    piv_real, piv_complex = np.zeros(size, dtype=np.int64), np.zeros(size, dtype=np.int64)
    f, y_new = np.zeros(size), np.zeros(size)
    Z0, Z, W, dW, F = np.zeros((3, size)), np.zeros((3, size)), np.zeros((3, size)), np.zeros((3, size)), \
        np.zeros((3, size))
    Q = np.zeros((size, 3))
    arg, scale, error, ZE = np.zeros(size), np.zeros(size), np.zeros(size), np.zeros(size)
    b_real, b_complex = np.zeros(size), np.zeros(size, dtype=np.complex128)
    newton = np.zeros(2)
    y_old, dy, f1 = np.zeros(size), np.zeros(size), np.zeros(size)
    samples, rows, values, when, row = watch_scratch(m, size)
    K = np.zeros((1, 1))
    t = t0
    for stretch in range(len(bounds)):
        t_bound, mid = bounds[stretch], mids[stretch]
        if t >= t_bound:
            continue
        state_rhs(m, t, y, t >= mid, f, work, Jscratch)
        counts[NFEV] += 1
        if fixed_h > 0:
            self_h_abs = fixed_h
        else:
            self_h_abs = initial_step(m, t, y, f, t_bound, np.int64(3), rtol, atol, mid, work, Jscratch, arg, y_new,
                                      scale)
            counts[NFEV] += 1
        self_h_abs_old, self_error_norm_old = -1.0, -1.0
        counts[NFEV] += state_jacobian(m, t, y, mid, rtol, atol, J, work, Jscratch, dy, arg, f1)
        counts[NJEV] += 1
        current_jac = True
        factored = False
        have_dense = False
        t_old, h_dense = t, 0.0
        while t < t_bound:
            min_step = 10 * abs(np.nextafter(t, np.inf) - t)
            if self_h_abs < min_step:
                h_abs, h_abs_old, error_norm_old = min_step, -1.0, -1.0
            else:
                h_abs, h_abs_old, error_norm_old = self_h_abs, self_h_abs_old, self_error_norm_old
            rejected = False
            safety = 0.0
            error_norm = 0.0
            while True:
                if h_abs < min_step:
                    floats[T_REACHED] = t
                    return TOO_SMALL_STEP, k, -1
                t_new = min(t + h_abs, t_bound)
                h = t_new - t
                h_abs = abs(h)
                if not have_dense:
                    Z0[:, :] = 0.0
                else:  # the last step's collocation polynomial, extrapolated
                    for r in range(3):
                        x = (t + h * C[r] - t_old) / h_dense
                        p1, p2, p3 = x, x * x, x * x * x
                        for i in range(size):
                            Z0[r, i] = Q[i, 0] * p1 + Q[i, 1] * p2 + Q[i, 2] * p3 + y_old[i] - y[i]
                for i in range(size):
                    scale[i] = atol[i] + abs(y[i]) * rtol
                converged = False
                while True:
                    if not factored:
                        counts[NLU] += 2
                        if not (factor_shifted(J, MU_REAL / h, 1.0, LU_real, piv_real)
                                and factor_shifted(J, MU_COMPLEX / h, 1.0, LU_complex, piv_complex)):
                            break
                        factored = True
                    converged = _collocation(m, t, y, h, Z0, scale, newton_tol, LU_real, LU_complex, piv_real,
                                             piv_complex, mid, Z, W, dW, F, arg, b_real, b_complex, work, Jscratch,
                                             counts, newton)
                    if converged or current_jac:
                        break
                    counts[NFEV] += state_jacobian(m, t, y, mid, rtol, atol, J, work, Jscratch, dy, arg, f1)
                    counts[NJEV] += 1
                    current_jac = True
                    factored = False
                if not converged:
                    h_abs *= 0.5
                    factored = False
                    counts[REJECTED] += 1
                    continue
                n_iter = newton[0]
                for i in range(size):
                    y_new[i] = y[i] + Z[2, i]
                    ZE[i] = (Z[0, i] * E[0] + Z[1, i] * E[1] + Z[2, i] * E[2]) / h
                    error[i] = f[i] + ZE[i]
                lu_solve(LU_real, piv_real, error)
                for i in range(size):
                    scale[i] = atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol
                error_norm = _rms_scaled(error.reshape((1, size)), scale)
                safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
                if rejected and error_norm > 1:
                    for i in range(size):
                        arg[i] = y[i] + error[i]
                    state_rhs(m, t, arg, t >= mid, error, work, Jscratch)
                    counts[NFEV] += 1
                    for i in range(size):
                        error[i] += ZE[i]
                    lu_solve(LU_real, piv_real, error)
                    error_norm = _rms_scaled(error.reshape((1, size)), scale)
                if error_norm > 1 and fixed_h <= 0:
                    factor = _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old)
                    h_abs *= max(MIN_FACTOR, safety * factor)
                    factored = False
                    rejected = True
                    counts[REJECTED] += 1
                else:
                    break
            recompute_jac = newton[0] > 2 and newton[1] > 1e-3
            factor = min(MAX_FACTOR, safety * _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old))
            if fixed_h > 0 or (not recompute_jac and factor < 1.2):
                factor = 1.0
            else:
                factored = False
            counts[ACCEPTED] += 1
            if counts[ACCEPTED] > max_steps:
                return STEP_BUDGET, k, -1
            self_h_abs_old = self_h_abs
            self_error_norm_old = error_norm
            self_h_abs = h_abs * factor
            # Dense output: Q = Z^T P, y(t_old + x h) = y_old + Q [x, x^2, x^3].
            for i in range(size):
                for q in range(3):
                    Q[i, q] = Z[0, i] * P[0, q] + Z[1, i] * P[1, q] + Z[2, i] * P[2, q]
            y_old[:] = y
            t_old, h_dense = t, h
            have_dense = True
            k, t_stop, fired = watch_step(m, np.int64(RADAU), t, t_new, h, y, y_new, K, F, Q, grid, k, mid, work,
                                          Jscratch, arg, skip_t, skip_guard, samples, rows, values, when, row, dy, out,
                                          out_a, out_t)
            if fired >= 0:
                return stop_at(m, y, row, t_stop, bound, floats), k, fired
            floats[T_REACHED] = t_new
            status = state_status(y_new, bound)
            if status != OK:
                return status, k, -1
            if recompute_jac:
                counts[NFEV] += state_jacobian(m, t_new, y_new, mid, rtol, atol, J, work, Jscratch, dy, arg, f1)
                counts[NJEV] += 1
                current_jac = True
            else:
                current_jac = False
            t = t_new
            y[:] = y_new
            state_rhs(m, t, y, t >= mid, f, work, Jscratch)
            counts[NFEV] += 1
    return OK, k, -1
