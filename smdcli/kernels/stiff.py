"""MATLAB's low-order stiff solvers compiled: ode23s, ode23t and ode23tb, with the model's analytic Jacobian.

The formulas, error estimates, simplified Newton iteration and step control are smdcli.solvers.integrators.stiff23's
(whose scipy-driven classes stay as the reference these kernels are tested against):

- ode23s: the Rosenbrock 2(3) pair of Shampine and Reichelt with its free second-order interpolant;
- ode23t: the trapezoidal rule, local error -h^3/12 y''' from y'' = J f + f_t at both ends of the step;
- ode23tb: TR-BDF2 (Hosea and Shampine 1996), a trapezoidal stage to t + gamma h and BDF2 to t + h sharing
  one iteration matrix.

The implicit ones filter their error estimate through the iteration matrix, as Shampine's codes do. The
integration restarts at every cut (force discontinuity).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import OK, STEP_BUDGET, TOO_SMALL_STEP, initial_step, scaled_rms, state_status
from smdcli.kernels.guards import HERMITE, ROSENBROCK, stop_at, watch_scratch, watch_step
from smdcli.kernels.linalg import factor_shifted, lu_solve
from smdcli.kernels.radau import EPS, newton_settled, newton_tolerance
from smdcli.kernels.rhs import state_jacobian, state_rhs
from smdcli.kernels.tableaus import ROS_D, ROSENBROCK23, TRAPEZOID

# Counters (ints): right-hand sides, accepted, rejected, Jacobians, factorizations.
NFEV, ACCEPTED, REJECTED, NJEV, NLU = range(5)
# Floats: time reached.
T_REACHED = 0

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.8, 0.2, 5.0
NEWTON_MAXITER = 5
ERROR_ORDER = 3  # every estimate here is O(h^3)

ROS_E32 = 6 + math.sqrt(2)
TR_GAMMA = 2 - math.sqrt(2)
TR_D = TR_GAMMA / 2
TR_C = (-3 * TR_GAMMA**2 + 4 * TR_GAMMA - 2) / (12 * (2 - TR_GAMMA))


@no_alloc
def _f(m, t, y, mid, dy, work, J, counts):
    """dy = f(t, y), counted, with the left limit of forces in the stretch's second half."""
    state_rhs(m, t, y, t >= mid, dy, work, J)
    counts[NFEV] += 1


@no_alloc
def _time_derivative(m, t, y, f, mid, T, trial_f, work, J, counts):
    """T = df/dt at fixed y by a forward difference; zero for an unforced model."""
    if len(m.f_kind) == 0:
        T[:] = 0.0
        return
    delta = math.sqrt(EPS) * max(abs(t), 1.0)
    _f(m, t + delta, y, mid, trial_f, work, J, counts)
    for i in range(len(y)):
        T[i] = (trial_f[i] - f[i]) / delta


@no_alloc
def _newton(m, method, t_eval, h, base, z, W, piv, scale, newton_tol, mid, dz, fz, work, J, counts):
    """Simplified Newton on z - base - c h f(t_eval, z) = 0 (c = d of the method), from the guess in z.
    base holds everything but the implicit term. True when it converged."""
    c = 0.5 if method == TRAPEZOID else TR_D
    linear = len(m.el_law) == 0
    old = -1.0
    for _ in range(NEWTON_MAXITER):
        _f(m, t_eval, z, mid, fz, work, J, counts)
        for i in range(len(z)):
            dz[i] = -(z[i] - base[i] - c * h * fz[i])
        lu_solve(W, piv, dz)
        for i in range(len(z)):
            z[i] += dz[i]
        if linear:  # the Jacobian is exact, so one iteration solves the linear system
            return True
        norm = scaled_rms(dz, scale)
        rate = -1.0
        if old >= 0:
            rate = norm / old if old > 0 else 0.0
            if rate >= 1:
                return False
        if newton_settled(rate, norm, newton_tol) or norm < 1e-3 * newton_tol:
            return True
        old = norm
    return False


@kernel
def integrate(m, method, y0, grid, cuts, rtol, atol, max_steps, bound, out, counts, floats, work, fixed_h):
    """Integrate from y0 = out[0] over the grid with ode23s, ode23t or ode23tb, restarting at each cut; a status.
    counts and floats receive the statistics named above; work is the right-hand side's scratch. fixed_h > 0
    takes steps of that size with no error control (for measuring a formula's order)."""
    y = y0.copy()
    none = np.zeros((0, 0))
    # int64 arguments, not literal ints: the overload the modes' runs compile and load, not a second one
    one, no_guard = np.int64(1), np.int64(-1)
    status, k, _ = integrate_mode(m, method, y, grid[0], cuts[1:], 0.5 * (cuts[:-1] + cuts[1:]), grid, one, rtol,
                                  atol, max_steps, bound, -np.inf, no_guard, out, none, none, counts, floats, work,
                                  fixed_h)
    if status != OK:
        out[k:] = np.nan
    return status


@kernel
def integrate_mode(m, method, y, t0, bounds, mids, grid, k, rtol, atol, max_steps, bound, skip_t, skip_guard, out,
                   out_a, out_t, counts, floats, work, fixed_h):
    """events.integrate_mode with ode23s, ode23t or ode23tb: from (t0, y) through the stretches ending at bounds
    (restarting at each), rows written from k, the mode's guards (if any) watched on the method's interpolant:
    (status, next row, guard fired or -1); y ends where it stopped."""
    floats[T_REACHED] = t0
    size = len(y)
    rtol = max(rtol, 100 * EPS)
    newton_tol = newton_tolerance(rtol)
    linear = len(m.el_law) == 0 and len(m.ns_belt) == 0  # a mode's Jacobian (its energy powers) varies
    J, J_new, W = np.zeros((size, size)), np.zeros((size, size)), np.zeros((size, size))
    piv = np.zeros(size, dtype=np.int64)
    f, y_new, f_new = np.zeros(size), np.zeros(size), np.zeros(size)
    k1, k2, k3, T = np.zeros(size), np.zeros(size), np.zeros(size), np.zeros(size)
    z1, f1, base, dz, fz = np.zeros(size), np.zeros(size), np.zeros(size), np.zeros(size), np.zeros(size)
    scale, err = np.zeros(size), np.zeros(size)
    second, second_new = np.zeros(size), np.zeros(size)
    samples, rows, values, when, row = watch_scratch(m, size)
    dy, arg = np.zeros(size), np.zeros(size)
    stages, Q, F = np.zeros((2, size)), np.zeros((1, 1)), np.zeros((1, 1))
    kind = ROSENBROCK if method == ROSENBROCK23 else HERMITE
    t = t0
    for stretch in range(len(bounds)):
        t_bound, mid = bounds[stretch], mids[stretch]
        if t >= t_bound:
            continue
        _f(m, t, y, mid, f, work, J, counts)
        counts[NFEV] += state_jacobian(m, t, y, mid, rtol, atol, J, work, J_new, dy, arg, fz)
        counts[NJEV] += 1
        jacobian_current = True  # J belongs to (t, y)
        second_t = math.nan  # the time at which `second` (y'') holds, for ode23t
        if fixed_h > 0:
            h = fixed_h
        else:  # scipy's starting step for an O(h^3) error estimate (order 2)
            h = initial_step(m, t, y, f, t_bound, np.int64(2), rtol, atol, mid, work, J_new, f_new, y_new, scale)
            counts[NFEV] += 1
        while t < t_bound:
            span = t_bound - t
            min_step = 10 * abs(np.nextafter(t, np.inf) - t)
            h = min(h, span)
            if span - h < min_step:  # do not leave a sliver before the bound
                h = span
            if not jacobian_current and not linear:
                counts[NFEV] += state_jacobian(m, t, y, mid, rtol, atol, J, work, J_new, dy, arg, fz)
                counts[NJEV] += 1
            jacobian_current = True
            rejected = False
            while True:
                if h < min_step:
                    floats[T_REACHED] = t
                    return TOO_SMALL_STEP, k, -1
                for i in range(size):
                    scale[i] = atol[i] + rtol * abs(y[i])
                converged = True
                if method == ROSENBROCK23:
                    _time_derivative(m, t, y, f, mid, T, fz, work, J_new, counts)
                    counts[NLU] += 1
                    if not factor_shifted(J, 1.0, h * ROS_D, W, piv):
                        converged = False
                    else:
                        for i in range(size):
                            k1[i] = f[i] + h * ROS_D * T[i]
                        lu_solve(W, piv, k1)
                        for i in range(size):
                            base[i] = y[i] + 0.5 * h * k1[i]
                        _f(m, t + 0.5 * h, base, mid, f1, work, J_new, counts)
                        for i in range(size):
                            k2[i] = f1[i] - k1[i]
                        lu_solve(W, piv, k2)
                        for i in range(size):
                            k2[i] += k1[i]
                            y_new[i] = y[i] + h * k2[i]
                        _f(m, t + h, y_new, mid, f_new, work, J_new, counts)
                        for i in range(size):
                            k3[i] = f_new[i] - ROS_E32 * (k2[i] - f1[i]) - 2 * (k1[i] - f[i]) + h * ROS_D * T[i]
                        lu_solve(W, piv, k3)
                        for i in range(size):
                            err[i] = h / 6 * (k1[i] - 2 * k2[i] + k3[i])
                elif method == TRAPEZOID:
                    counts[NLU] += 1
                    if not factor_shifted(J, 1.0, 0.5 * h, W, piv):
                        converged = False
                    else:
                        for i in range(size):
                            base[i] = y[i] + 0.5 * h * f[i]
                            y_new[i] = y[i] + h * f[i]
                        converged = _newton(m, method, t + h, h, base, y_new, W, piv, scale, newton_tol, mid, dz,
                                            fz, work, J_new, counts)
                    if converged:
                        _f(m, t + h, y_new, mid, f_new, work, J_new, counts)
                        if second_t != t:  # y'' = J f + f_t at the step's start
                            _time_derivative(m, t, y, f, mid, T, fz, work, J_new, counts)
                            for r in range(size):
                                s = T[r]
                                for q in range(size):
                                    s += J[r, q] * f[q]
                                second[r] = s
                            second_t = t
                        if linear:
                            J_new[:, :] = J
                        else:
                            counts[NFEV] += state_jacobian(m, t + h, y_new, mid, rtol, atol, J_new, work, J, dy, arg,
                                                           fz)
                            counts[NJEV] += 1
                        _time_derivative(m, t + h, y_new, f_new, mid, T, fz, work, J, counts)
                        for r in range(size):
                            s = T[r]
                            for q in range(size):
                                s += J_new[r, q] * f_new[q]
                            second_new[r] = s
                            err[r] = -(h * h / 12) * (second_new[r] - second[r])
                        lu_solve(W, piv, err)
                else:  # TRBDF2
                    counts[NLU] += 1
                    if not factor_shifted(J, 1.0, TR_D * h, W, piv):
                        converged = False
                    else:
                        for i in range(size):
                            base[i] = y[i] + TR_D * h * f[i]
                            z1[i] = y[i] + TR_GAMMA * h * f[i]
                        converged = _newton(m, method, t + TR_GAMMA * h, h, base, z1, W, piv, scale, newton_tol,
                                            mid, dz, fz, work, J_new, counts)
                    if converged:
                        _f(m, t + TR_GAMMA * h, z1, mid, f1, work, J_new, counts)
                        a1 = 1 / (TR_GAMMA * (2 - TR_GAMMA))
                        a0 = (1 - TR_GAMMA) ** 2 / (TR_GAMMA * (2 - TR_GAMMA))
                        for i in range(size):
                            base[i] = a1 * z1[i] - a0 * y[i]
                            y_new[i] = z1[i] + (1 - TR_GAMMA) * h * f1[i]
                        converged = _newton(m, method, t + h, h, base, y_new, W, piv, scale, newton_tol, mid, dz,
                                            fz, work, J_new, counts)
                    if converged:
                        _f(m, t + h, y_new, mid, f_new, work, J_new, counts)
                        g = TR_GAMMA
                        for i in range(size):
                            err[i] = TR_C * 2 * h * (f[i] / g - f1[i] / (g * (1 - g)) + f_new[i] / (1 - g))
                        lu_solve(W, piv, err)
                if not converged:
                    h *= 0.5
                    rejected = True
                    counts[REJECTED] += 1
                    continue
                for i in range(size):
                    scale[i] = atol[i] + rtol * max(abs(y[i]), abs(y_new[i]))
                error = scaled_rms(err, scale)
                if error <= 1 or fixed_h > 0:
                    break
                h *= min(1.0, max(MIN_FACTOR, SAFETY * error ** (-1.0 / ERROR_ORDER)))
                rejected = True
                counts[REJECTED] += 1
            if error == 0:
                factor = 1.0 if rejected else MAX_FACTOR
            else:
                factor = min(1.0 if rejected else MAX_FACTOR, max(MIN_FACTOR, SAFETY * error ** (-1.0 / ERROR_ORDER)))
            if fixed_h > 0:
                factor = 1.0
            t_new = t + h
            counts[ACCEPTED] += 1
            if counts[ACCEPTED] > max_steps:
                return STEP_BUDGET, k, -1
            for i in range(size):
                stages[0, i] = k1[i] if kind == ROSENBROCK else f[i]
                stages[1, i] = k2[i] if kind == ROSENBROCK else f_new[i]
            k, t_stop, fired = watch_step(m, kind, t, t_new, h, y, y_new, stages, F, Q, grid, k, mid, work,
                                          J_new, arg, skip_t, skip_guard, samples, rows, values, when, row, dy, out,
                                          out_a, out_t)
            if fired >= 0:
                return stop_at(m, y, row, t_stop, bound, floats), k, fired
            floats[T_REACHED] = t_new
            status = state_status(y_new, bound)
            if status != OK:
                return status, k, -1
            if method == TRAPEZOID:  # the new end's Jacobian and y'' start the next step
                J[:, :] = J_new
                second[:] = second_new
                second_t = t_new
            else:
                jacobian_current = linear
            t = t_new
            y[:] = y_new
            f[:] = f_new
            h *= factor
    return OK, k, -1
