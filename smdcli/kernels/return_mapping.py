"""The Newmark family (generalized-alpha: Newmark, Hilber-alpha, central difference are cases of it) on scenes with
hysteretic springs, compiled: each step's Newton iteration on the new acceleration evaluates every spring by its
return mapping from the last committed state (elastoplastic and bilinear: the trial force projected back onto the
yield surface; Bouc-Wen: z by the trapezoidal rule, solved by Newton), with its consistent tangent in the
iteration matrix, and commits the state only when the step has converged, as structural codes do:

    (1 - am) M a1 + am M a0 + C v_af + (1 - af) f(x1) + af f(x0) = F(t_af),
    x1 = x0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1),   v1 = v0 + h ((1 - gamma) a0 + gamma a1).

Every step's state, the springs' tensions and internal variables and the energy terms (trapezoid rule a step,
the method's order) are written out; smdcli.solvers.events.return_mapping puts them on the output grid. The elastic-
plastic return map is smdcli.elements.elastoplastic.return_map's, Bouc-Wen's step the trapezoidal rule on its
z' (tests hold them equal).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.arrays import CUBIC_SPRING
from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.linalg import lu_factor, lu_solve
from smdcli.elements.base import NEWMARK_CORE, NEWMARK_SMOOTH_Z
from smdcli.kernels.forces import force_value
from smdcli.kernels.rhs import element_force, z_step

# Spring rows (elements.base's NEWMARK_*): parameters (k, fy) of an elastic-plastic core, or ((1-alpha) k, A, beta,
# gamma, n) of a smooth hysteretic variable z
NEWTON_ITERATIONS = 50
NEWTON_TOLERANCE = 1e-12  # of the residual, relative to the forces' scale
OK, NEWTON_FAILED, STEP_BUDGET, DIVERGED = range(4)
STEPS, FACTORIZATIONS = range(2)  # counters (ints); floats[T_REACHED]: the time the run reached
T_REACHED = 0
# Energy terms written per step: input work, dissipated by dampers, hysteretic, strain (stored).
WORK, DISSIPATED, HYSTERETIC, STRAIN = range(4)


@no_alloc
def spring(law, p, committed, d0, d1, h):
    """(tension, tangent, trial state) of a hysteretic spring stepped from d0 to d1 over h from its committed state
    (the plastic deformation, or Bouc-Wen's z)."""
    if law == NEWMARK_SMOOTH_Z:
        z, dz = z_step(p, committed, d0, d1, h)
        return p[0] * z, p[0] * dz, z
    trial = p[0] * (d1 - committed)
    if abs(trial) <= p[1]:
        return trial, p[0], committed
    sign = 1.0 if trial > 0 else -1.0
    return sign * p[1], 0.0, d1 - sign * p[1] / p[0]


@no_alloc
def _stored(law, p, state, d):
    """What a spring stores at d in its committed state: the elastic part's strain energy."""
    if law == NEWMARK_SMOOTH_Z:
        return 0.5 * p[0] * state * state
    elastic = min(abs(d - state), p[1] / p[0])
    return 0.5 * p[0] * elastic * elastic


@no_alloc
def _internal(m, K, R, laws, par, committed, trial, x1, v1, x0, h, y, f, Kt, Ct, T, Tk):
    """f = K x1 + R^T T + f_nl(x1, v1) with each spring return-mapped from its committed state (trial states into
    trial), and the tangents Kt = K + R^T diag(dT/dd) R + K_nl, Ct = C_nl."""
    n = m.n
    for i in range(n):
        y[i] = x1[i]
        y[n + i] = v1[i]
        s = 0.0
        for j in range(n):
            s += K[i, j] * x1[j]
            Kt[i, j] = K[i, j]
            Ct[i, j] = 0.0
        f[i] = s
    for e in range(len(laws)):
        d1, d0 = 0.0, 0.0
        for i in range(n):
            d1 += R[e, i] * x1[i]
            d0 += R[e, i] * x0[i]
        T[e], Tk[e], trial[e] = spring(laws[e], par[e], committed[e], d0, d1, h)
        for i in range(n):
            if R[e, i] != 0.0:
                f[i] += R[e, i] * T[e]
                for j in range(n):
                    Kt[i, j] += R[e, i] * Tk[e] * R[e, j]
    for e in range(len(m.el_law)):
        g = element_force(m, e, y)
        a, b = m.el_a[e], m.el_b[e]
        cubic = m.el_law[e] == CUBIC_SPRING
        offset = 0 if cubic else n
        d = (y[offset + a] if a >= 0 else 0.0) - (y[offset + b] if b >= 0 else 0.0)
        slope = 3 * m.el_coef[e] * d * d if cubic else 2 * m.el_coef[e] * abs(d)
        target = Kt if cubic else Ct
        if a >= 0:
            f[a] += g
            target[a, a] += slope
        if b >= 0:
            f[b] -= g
            target[b, b] += slope
        if a >= 0 and b >= 0:
            target[a, b] -= slope
            target[b, a] -= slope


@no_alloc
def _applied(m, M, t, mid, F, stack):
    """F(t): the applied forces, the ground's acceleration as -M 1 a_g (left limits past mid)."""
    n = m.n
    ground = 0.0
    for i in range(n):
        F[i] = 0.0
    for j in range(len(m.f_kind)):
        value = force_value(m, j, t, t >= mid, stack)
        if m.f_dof[j] >= 0:
            F[m.f_dof[j]] += value
        else:
            ground += value
    if ground != 0.0:
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += M[i, j]
            F[i] -= ground * s


@no_alloc
def _energies(m, K, C, R, laws, par, committed, x, v):
    """(what the springs store, the strain energy of everything, the dampers' power) at (x, v), committed states."""
    n = m.n
    stored = 0.0
    for e in range(len(laws)):
        d = 0.0
        for i in range(n):
            d += R[e, i] * x[i]
        stored += _stored(laws[e], par[e], committed[e], d)
    strain, power = stored, 0.0
    for i in range(n):
        for j in range(n):
            strain += 0.5 * x[i] * K[i, j] * x[j]
            power += v[i] * C[i, j] * v[j]
    for e in range(len(m.el_law)):
        a, b = m.el_a[e], m.el_b[e]
        cubic = m.el_law[e] == CUBIC_SPRING
        src = x if cubic else v
        d = (src[a] if a >= 0 else 0.0) - (src[b] if b >= 0 else 0.0)
        if cubic:
            strain += 0.25 * m.el_coef[e] * d ** 4
        else:
            power += m.el_coef[e] * abs(d) * d * d
    return stored, strain, power


@kernel
def march(m, M, C, K, R, laws, par, coefficients, x, v, committed, edges, jump_dx, jump_dv, dt, max_steps, bound,
          t_out, x_out, v_out, a_out, T_out, q_out, e_out, counts, floats, stack):
    """Step from (x, v) at edges[0] through edges (restarting from equilibrium at each ground jump: jump_dx/dv
    rows, zero elsewhere), writing every step's time, state, tensions, internal variables and energies into the
    *_out rows from 0; returns (status, rows written). counts: STEPS, FACTORIZATIONS; floats: T_REACHED; stack:
    the forces' scratch (rhs.work_size)."""
    n = m.n
    E = len(laws)
    am, af, beta, gamma = coefficients[0], coefficients[1], coefficients[2], coefficients[3]
    y, f, f_prev, F, F_step, F_end = np.zeros(2 * n), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    Kt, Ct, J, piv = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n)), np.zeros(n, dtype=np.int64)
    T, Tk, trial = np.zeros(E), np.zeros(E), np.zeros(E)
    a, a1, x1, v1, r = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    x_old, v_old = np.zeros(n), np.zeros(n)
    acc = np.zeros(3)  # work, dissipated, loop work (on the springs' hysteretic parts)
    stored0 = 0.0
    row = np.int64(0)  # not a literal: one compile of _write
    t = edges[0]
    for edge in range(len(edges) - 1):
        ta, tb = edges[edge], edges[edge + 1]
        mid = 0.5 * (ta + tb)
        if edge == 0 or jump_dx[edge].any() or jump_dv[edge].any():  # a start from equilibrium
            _, strain_before, _ = _energies(m, K, C, R, laws, par, committed, x, v)
            for i in range(n):
                x_old[i], v_old[i] = x[i], v[i]
                x[i] += jump_dx[edge, i]
                v[i] += jump_dv[edge, i]
            _internal(m, K, R, laws, par, committed, trial, x, v, x, 0.0, y, f_prev, Kt, Ct, T, Tk)
            lost = 0.0  # a spring yielding through the jump dissipates fy |change of d_p|
            for e in range(E):
                if laws[e] == NEWMARK_CORE:
                    lost += par[e, 1] * abs(trial[e] - committed[e])
                committed[e] = trial[e]
            _applied(m, M, ta, mid, F_end, stack)
            for i in range(n):
                s = F_end[i] - f_prev[i]
                for j in range(n):
                    s -= C[i, j] * v[j]
                    J[i, j] = M[i, j]
                a[i] = s
            lu_factor(J, piv)
            lu_solve(J, piv, a)
            stored, strain, _ = _energies(m, K, C, R, laws, par, committed, x, v)
            if edge == 0:
                stored0 = stored
            else:  # the wall ends jumped: the ground did that work, what the springs dissipated on the way included
                acc[0] += _kinetic(M, v) + strain - _kinetic(M, v_old) - strain_before + lost
                acc[2] = e_out[row - 1, HYSTERETIC] + lost + stored - stored0
            row = _write(row, t, x, v, a, T, committed, acc, stored0, stored, strain, t_out, x_out, v_out, a_out, T_out,
                         q_out, e_out)
        count = max(1, math.ceil((tb - ta) / dt * (1 - 1e-12)))
        h = (tb - ta) / count
        for step in range(count):
            t1 = ta + (step + 1) * h if step + 1 < count else tb
            _applied(m, M, (1 - af) * t1 + af * t, mid, F, stack)
            for i in range(n):
                a1[i] = a[i]
            converged = False
            for _ in range(NEWTON_ITERATIONS):
                for i in range(n):
                    x1[i] = x[i] + h * v[i] + h * h * ((0.5 - beta) * a[i] + beta * a1[i])
                    v1[i] = v[i] + h * ((1 - gamma) * a[i] + gamma * a1[i])
                _internal(m, K, R, laws, par, committed, trial, x1, v1, x, h, y, f, Kt, Ct, T, Tk)
                scale = 1e-300
                worst = 0.0
                for i in range(n):
                    ma1, s = 0.0, 0.0
                    for j in range(n):
                        ma1 += M[i, j] * a1[j]
                        s += (1 - am) * M[i, j] * a1[j] + am * M[i, j] * a[j] + C[i, j] * ((1 - af) * v1[j] + af * v[j])
                    r[i] = s + (1 - af) * f[i] + af * f_prev[i] - F[i]
                    scale = max(scale, abs(F[i]), abs(f[i]), abs(ma1))
                    worst = max(worst, abs(r[i]))
                if worst <= NEWTON_TOLERANCE * scale:
                    converged = True
                    break
                for i in range(n):
                    for j in range(n):
                        J[i, j] = (1 - am) * M[i, j] + (1 - af) * (gamma * h * (C[i, j] + Ct[i, j])
                                                                     + beta * h * h * Kt[i, j])
                lu_factor(J, piv)
                lu_solve(J, piv, r)
                counts[FACTORIZATIONS] += 1
                for i in range(n):
                    a1[i] -= r[i]
            counts[STEPS] += 1
            floats[T_REACHED] = t
            if not converged:
                return NEWTON_FAILED, row
            if counts[STEPS] > max_steps:
                return STEP_BUDGET, row
            for i in range(n):
                if not math.isfinite(x1[i]) or abs(x1[i]) > bound:
                    return DIVERGED, row
            # the step's work and dissipation by the trapezoid rule; the springs' loop work by their mean force
            _applied(m, M, t1, mid, F_step, stack)
            _, _, power_before = _energies(m, K, C, R, laws, par, committed, x, v)
            loop = 0.0
            for e in range(E):
                dd = 0.0
                for i in range(n):
                    dd += R[e, i] * (x1[i] - x[i])
                loop += 0.5 * (T_out[row - 1, e] + T[e]) * dd
            for e in range(E):
                committed[e] = trial[e]
            stored, strain, power = _energies(m, K, C, R, laws, par, committed, x1, v1)
            work = 0.0
            for i in range(n):
                work += F_end[i] * v[i] + F_step[i] * v1[i]
            acc[0] += 0.5 * h * work
            acc[1] += 0.5 * h * (power_before + power)
            acc[2] += loop
            for i in range(n):
                x[i], v[i], a[i], f_prev[i], F_end[i] = x1[i], v1[i], a1[i], f[i], F_step[i]
            t = t1
            floats[T_REACHED] = t
            row = _write(row, t, x, v, a, T, committed, acc, stored0, stored, strain, t_out, x_out, v_out, a_out, T_out,
                         q_out, e_out)
    return OK, row


@no_alloc
def _kinetic(M, v):
    """1/2 v^T M v."""
    total = 0.0
    for i in range(len(v)):
        for j in range(len(v)):
            total += 0.5 * v[i] * M[i, j] * v[j]
    return total


@no_alloc
def _write(row, t, x, v, a, T, committed, acc, stored0, stored, strain, t_out, x_out, v_out, a_out, T_out, q_out,
           e_out):
    """One step's row of the outputs; returns the next row."""
    t_out[row] = t
    for i in range(len(x)):
        x_out[row, i], v_out[row, i], a_out[row, i] = x[i], v[i], a[i]
    for e in range(len(T)):
        T_out[row, e], q_out[row, e] = T[e], committed[e]
    e_out[row, WORK], e_out[row, DISSIPATED] = acc[0], acc[1]
    e_out[row, HYSTERETIC] = acc[2] - (stored - stored0)
    e_out[row, STRAIN] = strain
    return row + 1
