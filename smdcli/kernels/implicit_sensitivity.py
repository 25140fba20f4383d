"""Compiled forward sensitivities of a stiff smooth scene: the state stepped by Radau IIA 5 (kernels.radau's
collocation, simplified Newton and step control), its sensitivities S = dy/dp by the same collocation formula.

After the state's stages Z have converged, S's stages follow from the formula differentiated (the staggered direct
method): dZ = h (A x I) (J(stage) (s0 + dZ) + df/dp(stage)), one linear system of 3 s unknowns, its matrix
I - h A_rc J_c factored once for every parameter, so that S is the exact derivative of the discrete solution, not an
iteration's. Radau's error estimate, (mu/h - J)^-1 (y' + sum E_r Z_r / h), is taken of S too, and the step
controlled on both. J and df/dp at a stage are sensitivity.augmented_rates' at [stage; 0]. A Bouc-Wen kink (d' or z
changing sign) ends a step just past it, on the branch of J the step started on, as the explicit kernel ends one.

Every output time is landed on; the kernel's arguments, outputs and statuses are kernels.sensitivity.integrate's,
so that a run turns to this one where that one finds the scene stiff.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import NOT_FINITE, OK, STEP_BUDGET, TOO_SMALL_STEP, assign, initial_step, scaled_rms
from smdcli.kernels.linalg import factor_shifted, lu_factor, lu_solve
from smdcli.kernels.radau import (C, E, EPS, MAX_FACTOR, MIN_FACTOR, MU_COMPLEX, MU_REAL, NEWTON_MAXITER, P as DENSE,
                                  _collocation, _predict_factor, newton_tolerance)
from smdcli.kernels.rhs import state_jacobian
from smdcli.kernels.sensitivity import augmented_rates, branches, kink_landing

S6 = 6**0.5
A = np.array([  # Radau IIA's collocation matrix (Hairer and Wanner IV.5, Table 5.6): Z = h (A x I) F
    [(88 - 7 * S6) / 360, (296 - 169 * S6) / 1800, (-2 + 3 * S6) / 225],
    [(296 + 169 * S6) / 1800, (88 + 7 * S6) / 360, (-2 - 3 * S6) / 225],
    [(16 - S6) / 36, (16 + S6) / 36, 1 / 9]])
STAGE, END, START = 0, 3, 4  # _evaluate's points: the stages 0..2 at [y + Z_r; 0], the step's end, a fresh start


@no_alloc
def _evaluate(first, last, m, models, weights, owner, ratios, moves, t, h, mid, y, y_new, Z, arg, R, K0, K_end,
              Js, work, J, dwork, f, g, signs):
    """augmented_rates at the points first .. last - 1 (STAGE + r: into R[r], J into Js[r]; END: [y_new] into K_end;
    START: y into K0), from one inlined call site. At a stage the sensitivities are 0, so its rates' S part is
    df/dp there and J is the stage's."""
    size_all = len(y)
    size = len(Z[0])
    for point in range(first, last):
        if point < END:
            for i in range(size):
                arg[i] = y[i] + Z[point, i]
            for i in range(size, size_all):
                arg[i] = 0.0
            ts = t + C[point] * h
        elif point == END:
            assign(arg, y_new)
            ts = t + h
        else:
            assign(arg, y)
            ts = t
        target = R[point] if point < END else K_end if point == END else K0
        augmented_rates(m, models, weights, owner, ratios, moves, g, ts, arg, ts >= mid, target, work, J, dwork, f,
                        signs)
        if point < END:
            s = J.shape[0]
            for i in range(s):
                for c in range(s):
                    Js[point, i, c] = J[i, c]


@no_alloc
def _sensitivity_stages(y, h, R, K0, Js, big, piv, column, DS, size):
    """DS (3, s, P): the sensitivities' stage increments from the stages' J (Js) and df/dp (R[r][size:]), each
    parameter's column of (I - h A_rc J_c) dZ = h A_rc (J_c s0 + df/dp_c) solved by one factorization; False where
    it is singular."""
    s = Js.shape[1]
    P = DS.shape[2]
    for r in range(3):
        for c in range(3):
            for i in range(s):
                for j in range(s):
                    big[r * s + i, c * s + j] = -h * A[r, c] * Js[c, i, j]
        for i in range(s):
            big[r * s + i, r * s + i] += 1.0
    if not lu_factor(big, piv):
        return False
    for p in range(P):
        for r in range(3):
            for i in range(s):
                total = 0.0
                for c in range(3):
                    rate = R[c, size + i * P + p]  # df/dp at stage c
                    for j in range(s):
                        rate += Js[c, i, j] * y[size + j * P + p]
                    total += A[r, c] * rate
                column[r * s + i] = h * total
        lu_solve(big, piv, column)
        for r in range(3):
            for i in range(s):
                DS[r, i, p] = column[r * s + i]
    return True


@kernel
def integrate(m, models, weights, owner, ratios, moves, y0, grid, cuts, rtol, atol, max_steps, out, rates, work,
              counts, reached):
    """kernels.sensitivity.integrate's run (the same arguments, outputs and statuses) by Radau IIA 5."""
    size_all = len(y0)
    n = m.n
    s = 2 * n + m.ns_q
    size = s + m.ns_acc
    P = (size_all - size) // s if s else 0
    J, dwork, f, g = np.zeros((s, s)), np.zeros((n, s)), np.zeros(size), np.zeros(n)
    signs, now = np.ones((len(m.ns_belt), 2)), np.ones((len(m.ns_belt), 2))
    newton_J, LU_real = np.zeros((size, size)), np.zeros((size, size))
    LU_complex = np.zeros((size, size), dtype=np.complex128)
    piv_real, piv_complex = np.zeros(size, dtype=np.int64), np.zeros(size, dtype=np.int64)
    Z0, Z, W, dW, F = np.zeros((3, size)), np.zeros((3, size)), np.zeros((3, size)), np.zeros((3, size)), \
        np.zeros((3, size))
    Q = np.zeros((size, 3))
    R, K0, K_end = np.zeros((3, size_all)), np.zeros(size_all), np.zeros(size_all)
    Js, DS = np.zeros((3, s, s)), np.zeros((3, s, P))
    big, piv, column = np.zeros((3 * s, 3 * s)), np.zeros(3 * s, dtype=np.int64), np.zeros(3 * s)
    y_new, y_old, arg = np.zeros(size_all), np.zeros(size_all), np.zeros(size_all)
    scale, error = np.zeros(size_all), np.zeros(size_all)
    b_real, b_complex = np.zeros(size), np.zeros(size, dtype=np.complex128)
    dy, f1, pad = np.zeros(size), np.zeros(size), np.zeros(size)
    newton_atol = atol[:size].copy()  # the energy terms ride along out of control (atol inf): a finite step for J
    for i in range(size):
        if not math.isfinite(newton_atol[i]):
            newton_atol[i] = 1.0
    return _march(m, models, weights, owner, ratios, moves, y0.copy(), grid, cuts, max(rtol, 100 * EPS), atol,
                  max_steps, out, rates, work, counts, reached, J, dwork, f, g, signs, now, newton_J, LU_real,
                  LU_complex, piv_real, piv_complex, Z0, Z, W, dW, F, Q, R, K0, K_end, Js, DS, big, piv,
                  column, y_new, y_old, arg, scale, error, b_real, b_complex, dy, f1, pad, np.zeros(2),
                  np.zeros((1, 1)), newton_atol)


@no_alloc
def _march(m, models, weights, owner, ratios, moves, y, grid, cuts, rtol, atol, max_steps, out, rates, work, counts,
           reached, J, dwork, f, g, signs, now, newton_J, LU_real, LU_complex, piv_real, piv_complex, Z0, Z, W, dW, F,
           Q, R, K0, K_end, Js, DS, big, piv, column, y_new, y_old, arg, scale, error, b_real, b_complex, dy, f1, pad,
           newton, Jscratch, newton_atol):
    """integrate's steps, on the scratch it made (compiled without reference counting): each segment between cuts
    started afresh (its rates, the Newton matrix, Hairer's first step on the state), each step's state by Radau's
    simplified Newton, then its sensitivities (_sensitivity_stages), the error of both, a kink ending it early."""
    size_all = len(y)
    size = Z.shape[1]
    s = J.shape[0]
    P = DS.shape[2]
    newton_tol = newton_tolerance(rtol)
    state = y[:size]
    stage, end, start = np.int64(STAGE), np.int64(END), np.int64(START)  # not literals: _evaluate compiles once
    assign(out[0], y)
    k = np.int64(1)
    pending = 0  # rates[0]: the first segment's start
    h_abs = 0.0
    for seg in range(len(cuts)):
        ta = cuts[seg]
        t_end = cuts[seg + 1] if seg + 1 < len(cuts) else ta
        mid = 0.5 * (ta + t_end) if seg + 1 < len(cuts) else np.inf  # the empty last one: the end's right limit
        t = ta
        # the state's rates say the branches, then the start's rates on them
        _evaluate(start, start + 1, m, models, weights, owner, ratios, moves, t, 0.0, mid, y, y_new, Z, arg, R, K0,
                  K_end, Js, work, J, dwork, f, g, signs)
        branches(m, y, K0, signs)
        _evaluate(start, start + 1, m, models, weights, owner, ratios, moves, t, 0.0, mid, y, y_new, Z, arg, R, K0,
                  K_end, Js, work, J, dwork, f, g, signs)
        counts[0] += 2
        if pending >= 0:
            assign(rates[pending], K0)
            pending = -1
        if t >= t_end:
            break
        if h_abs == 0.0:  # later segments go on at the pace the first reached
            h_abs = initial_step(m, t, state, K0[:size], t_end, np.int64(3), rtol, atol[:size], mid, work, Jscratch,
                                 f1, dy, pad)
            counts[0] += 1
        h_abs_old, error_old = -1.0, -1.0
        counts[0] += state_jacobian(m, t, state, mid, rtol, newton_atol, newton_J, work, Jscratch, dy, pad, f1)
        current_jac, factored, have_dense = True, False, False
        h_factored = 0.0
        t_old, h_dense = t, 0.0
        while t < t_end:
            target = grid[k] if k < len(grid) and grid[k] < t_end else t_end
            min_step = 10 * abs(np.nextafter(t, np.inf) - t)
            rejected = False
            landed = np.int64(0)  # not a literal: kink_landing compiles once
            error_norm, safety = 0.0, 0.0
            while True:
                if h_abs < min_step:
                    reached[0] = t
                    return TOO_SMALL_STEP
                t_new = min(t + h_abs, target)
                h = t_new - t
                if not have_dense:
                    Z0[:, :] = 0.0
                else:  # the last step's collocation polynomial, extrapolated
                    for r in range(3):
                        x = (t + h * C[r] - t_old) / h_dense
                        for i in range(size):
                            Z0[r, i] = Q[i, 0] * x + Q[i, 1] * x * x + Q[i, 2] * x * x * x + y_old[i] - y[i]
                for i in range(size):
                    scale[i] = atol[i] + abs(y[i]) * rtol
                converged = False
                while True:
                    if not factored or h != h_factored:
                        if not (factor_shifted(newton_J, MU_REAL / h, 1.0, LU_real, piv_real)
                                and factor_shifted(newton_J, MU_COMPLEX / h, 1.0, LU_complex, piv_complex)):
                            break
                        factored, h_factored = True, h
                    converged = _collocation(m, t, state, h, Z0, scale[:size], newton_tol, LU_real, LU_complex,
                                             piv_real, piv_complex, mid, Z, W, dW, F, f1, b_real, b_complex, work,
                                             Jscratch, counts, newton)
                    if converged or current_jac:
                        break
                    counts[0] += state_jacobian(m, t, state, mid, rtol, newton_atol, newton_J, work, Jscratch, dy,
                                                pad, f1)
                    current_jac, factored = True, False
                if converged and P > 0:  # the state alone (the first pass) has none to solve
                    _evaluate(stage, stage + 3, m, models, weights, owner, ratios, moves, t, h, mid, y, y_new, Z, arg,
                              R, K0, K_end, Js, work, J, dwork, f, g, signs)
                    counts[0] += 3
                    converged = _sensitivity_stages(y, h, R, K0, Js, big, piv, column, DS, size)
                if not converged:
                    h_abs = 0.5 * abs(h)
                    factored = False
                    rejected = True
                    counts[2] += 1
                    continue
                for i in range(size):
                    y_new[i] = y[i] + Z[2, i]
                for i in range(s):
                    for p in range(P):
                        y_new[size + i * P + p] = y[size + i * P + p] + DS[2, i, p]
                # a kink of the law inside the step (the stages' state rates at its end stand for the end's)
                again = kink_landing(m, y, y_new, K0, F[2], h, landed, min_step)
                if again > 0.0:
                    landed += 1
                    h_abs = again
                    counts[2] += 1
                    continue
                # Radau's error estimate, (mu/h - J)^-1 (y' + sum E_r Z_r / h), of the state and of each column of S
                for i in range(size):
                    error[i] = K0[i] + (Z[0, i] * E[0] + Z[1, i] * E[1] + Z[2, i] * E[2]) / h
                lu_solve(LU_real, piv_real, error[:size])
                for p in range(P):
                    for i in range(size):
                        pad[i] = 0.0 if i >= s else (K0[size + i * P + p] + (DS[0, i, p] * E[0] + DS[1, i, p] * E[1]
                                                                           + DS[2, i, p] * E[2]) / h)
                    lu_solve(LU_real, piv_real, pad)  # the energy terms' rows do not reach the others
                    for i in range(s):
                        error[size + i * P + p] = pad[i]
                for i in range(size_all):
                    scale[i] = atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol
                error_norm = scaled_rms(error, scale)
                safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + newton[0])
                if error_norm > 1:
                    h_abs = abs(h) * max(MIN_FACTOR, safety * _predict_factor(abs(h), h_abs_old, error_norm,
                                                                              error_old))
                    rejected = True
                    counts[2] += 1
                    continue
                break
            recompute_jac = newton[0] > 2 and newton[1] > 1e-3
            factor = min(MAX_FACTOR, safety * _predict_factor(abs(h), h_abs_old, error_norm, error_old))
            if rejected:
                factor = min(1.0, factor)
            elif not recompute_jac and factor < 1.2:  # scipy's: the same step, its factorizations kept
                factor = 1.0
            if t_new < target or abs(h) >= h_abs:  # a step cut short to land sets no pace for the next
                h_abs_old, error_old = abs(h), error_norm
                h_abs = abs(h) * factor
            counts[1] += 1
            reached[0] = t
            if counts[1] > max_steps:
                return STEP_BUDGET
            for i in range(size_all):
                if not math.isfinite(y_new[i]):
                    return NOT_FINITE
            for i in range(size):  # dense output of the state: y(t + x h) = y + Q [x, x^2, x^3]
                for q in range(3):
                    Q[i, q] = Z[0, i] * DENSE[0, q] + Z[1, i] * DENSE[1, q] + Z[2, i] * DENSE[2, q]
            assign(y_old, y)
            t_old, h_dense, have_dense = t, h, True
            _evaluate(end, end + 1, m, models, weights, owner, ratios, moves, t, h, mid, y, y_new, Z, arg, R, K0,
                      K_end, Js, work, J, dwork, f, g, signs)
            counts[0] += 1
            t = t_new
            assign(y, y_new)
            assign(K0, K_end)
            branches(m, y, K0, now)
            crossed = False
            for e in range(len(now)):
                crossed = crossed or now[e, 0] != signs[e, 0] or now[e, 1] != signs[e, 1]
                signs[e, 0], signs[e, 1] = now[e, 0], now[e, 1]
            if crossed and t < t_end:  # a kink crossed: the rates on the new branch, the Newton matrix anew
                _evaluate(start, start + 1, m, models, weights, owner, ratios, moves, t, 0.0, mid, y, y_new, Z, arg,
                          R, K0, K_end, Js, work, J, dwork, f, g, signs)
                counts[0] += 1
                recompute_jac = True
            if recompute_jac and t < t_end:
                counts[0] += state_jacobian(m, t, state, mid, rtol, newton_atol, newton_J, work, Jscratch, dy, pad,
                                            f1)
                current_jac, factored = True, False
            else:
                current_jac = False
            if k < len(grid) and t == grid[k]:
                assign(out[k], y)
                if t >= t_end:  # at a cut the right limit: the next segment's start
                    pending = k
                else:
                    assign(rates[k], K0)
                k += 1
    return OK
