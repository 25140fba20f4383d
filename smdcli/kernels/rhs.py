"""Compiled forces, right-hand side and Jacobian of M x'' + C x' + K x + f_nl(x, x') = B u(t).

Every function reads a ModelArrays (smdcli.kernels.arrays); the forces' values are smdcli.kernels.forces'.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.elements.base import SMOOTH_NONE
from smdcli.elements.bouc_wen import SMOOTH_BOUC_WEN
from smdcli.elements.friction import SMOOTH_STRIBECK, SMOOTH_TANH
from smdcli.kernels.arrays import CUBIC_SPRING
from smdcli.kernels.compiler import inlined, kernel, no_alloc
from smdcli.kernels.forces import force_value
from smdcli.shapes.expression import EXPRESSION

@inlined
def element_force(m, e, y):
    """Force of nonlinear element e in state y = [x; v] (k3 d^3 or c |d'| d', d = x_a - x_b)."""
    n = m.n
    a, b = m.el_a[e], m.el_b[e]
    offset = 0 if m.el_law[e] == CUBIC_SPRING else n
    d = (y[offset + a] if a >= 0 else 0.0) - (y[offset + b] if b >= 0 else 0.0)
    if m.el_law[e] == CUBIC_SPRING:
        return m.el_coef[e] * d * d * d
    return m.el_coef[e] * abs(d) * d


@inlined
def rhs(m, t, y, left, dy, work):
    """dy = [v; M^-1 (B u(t) - C v - K x - f_nl)] for y = [x; v]; work is scratch of length work_size(m). A
    nonsmooth scene in one mode (m.ns_belt not empty) has y = [x, v, q, energy]: the mode's projected motion,
    the laws' internal rates and the energy terms' powers, its elements' tensions left in work[n:n + E]. (The
    mode's parts are calls, not inlined: inlined into every stage of every integrator they doubled the compile.)"""
    n = m.n
    E = len(m.ns_belt)
    for i in range(n):
        dy[i] = y[n + i]
        work[i] = 0.0
    stack = work[n + E:]
    ground = 0.0  # relative coordinates: M^-1 (-M 1 a_g) is -a_g on every DOF
    power = 0.0  # what the applied forces put in
    for j in range(len(m.f_kind)):
        value = force_value(m, j, t, left, stack)
        if m.f_dof[j] >= 0:
            work[m.f_dof[j]] += value
            power += value * y[n + m.f_dof[j]]
        else:
            ground += value
    for e in range(len(m.el_law)):
        g = element_force(m, e, y)
        if m.el_a[e] >= 0:
            work[m.el_a[e]] -= g
        if m.el_b[e] >= 0:
            work[m.el_b[e]] += g
    if E > 0:
        _mode_forces(m, y, work)
    for i in range(n):
        s = 0.0
        for k in range(m.a_ptr[i], m.a_ptr[i + 1]):
            s += m.a_val[k] * y[m.a_idx[k]]
        for k in range(m.mi_ptr[i], m.mi_ptr[i + 1]):
            s += m.mi_val[k] * work[m.mi_idx[k]]
        dy[n + i] = s - ground * (m.ground_row[i] if E > 0 else 1.0)
    if E > 0:
        _mode_rates(m, y, ground, power, dy, work)


@inlined
def _element_motion(m, e, y):
    """(d, d') of nonsmooth element e at y."""
    n = m.n
    d = 0.0
    rate = m.ns_belt[e]
    for i in range(n):
        r = m.ns_R[e, i]
        if r != 0.0:
            d += r * y[i]
            rate += r * y[n + i]
    return d, rate


@inlined
def bouc_wen_rate(p, z, rate):
    """Bouc-Wen's dz/dt at z and d' for parameters p = ((1 - alpha) k, A, beta, gamma, n, ...)."""
    size = abs(z)
    return p[1] * rate - p[2] * abs(rate) * size ** (p[4] - 1) * z - p[3] * rate * size ** p[4]


@no_alloc
def bouc_wen_partials(p, z, rate):
    """(d z_rate / d z, d z_rate / d d')."""
    size = abs(z)
    sign_z = 1.0 if z >= 0 else -1.0
    sign_rate = 1.0 if rate >= 0 else -1.0
    power = size ** (p[4] - 1)
    by_z = -p[2] * abs(rate) * p[4] * power - p[3] * rate * p[4] * power * sign_z
    by_rate = p[1] - p[2] * sign_rate * power * z - p[3] * size ** p[4]
    return by_z, by_rate


@no_alloc
def z_step(p, z_old, d_old, d_new, h):
    """(z, dz/dd_new) after a step from d_old to d_new over h: the trapezoidal rule at the step's mean rate."""
    if h <= 0:
        return z_old, 0.0
    rate = (d_new - d_old) / h
    start = bouc_wen_rate(p, z_old, rate)
    z = z_old + h * start
    for _ in range(50):
        by_z, _ = bouc_wen_partials(p, z, rate)
        f = z - z_old - 0.5 * h * (start + bouc_wen_rate(p, z, rate))
        step = f / (1.0 - 0.5 * h * by_z)
        z -= step
        if abs(step) <= 1e-15 * max(abs(z), abs(z_old), 1e-300):
            break
    by_z, by_rate = bouc_wen_partials(p, z, rate)
    _, by_rate_old = bouc_wen_partials(p, z_old, rate)
    return z, 0.5 * (by_rate_old + by_rate) / (1.0 - 0.5 * h * by_z)


@inlined
def _smooth_tension(m, e, rate, y):
    """The smooth part of element e's tension (Bouc-Wen's (1 - alpha) k z, Stribeck's or tanh's friction)."""
    law = m.ns_law[e]
    p = m.ns_par[e]
    if law == SMOOTH_BOUC_WEN:
        return p[0] * y[2 * m.n + int(p[5])]
    if law == SMOOTH_STRIBECK:
        return p[0] * (p[1] + (p[2] - p[1]) * math.exp(-(rate / p[3]) ** 2))
    if law == SMOOTH_TANH:
        return p[0] * math.tanh(rate / p[1])
    return 0.0


@no_alloc
def _mode_forces(m, y, work):
    """The mode's constant forces and its free elements' smooth tensions into the force work[:n]; every free
    element's tension into work[n + e]."""
    n = m.n
    for i in range(n):
        work[i] += m.f_const[i]
    for e in range(len(m.ns_belt)):
        if m.ns_held[e]:
            continue
        d, rate = _element_motion(m, e, y)
        extra = _smooth_tension(m, e, rate, y)
        if extra != 0.0:
            for i in range(n):
                work[i] -= extra * m.ns_R[e, i]
        work[n + e] = m.ns_stiff[e] * d + m.ns_damp[e] * rate + m.ns_const[e] + extra


@no_alloc
def _mode_rates(m, y, ground, power, dy, work):
    """The held elements' tensions (the constraints' forces), the laws' internal rates, the energy powers."""
    n = m.n
    E = len(m.ns_belt)
    acc = 2 * n + m.ns_q
    for e in range(E):
        if m.ns_held[e]:
            T = -m.h_g[e] * ground
            for c in range(2 * n):
                T += m.h_lin[e, c] * y[c]
            for i in range(n):
                T += m.h_f[e, i] * work[i]
            work[n + e] = T
    for k in range(m.ns_acc):
        dy[acc + k] = 0.0
    dissipated = 0.0
    for i in range(n):
        row = 0.0
        for j in range(n):
            row += m.c_dense[i, j] * y[n + j]
        dissipated += y[n + i] * row
        power -= ground * m.mass_row[i] * y[n + i]
    for e in range(len(m.el_law)):
        if m.el_law[e] != CUBIC_SPRING:
            a, b = m.el_a[e], m.el_b[e]
            d = (y[n + a] if a >= 0 else 0.0) - (y[n + b] if b >= 0 else 0.0)
            dissipated += m.el_coef[e] * abs(d) * d * d
    for e in range(E):
        d, rate = _element_motion(m, e, y)
        power += work[n + e] * m.ns_belt[e]  # a belt's work on its contact
        term = m.ns_term[e]
        if term < 0:
            continue
        p = m.ns_par[e]
        loss = (m.ns_pd[e] * rate + m.ns_pc[e] + m.ns_px[e] * d) * rate
        law = m.ns_law[e]
        if law == SMOOTH_BOUC_WEN:
            z = y[2 * n + int(p[5])]
            z_rate = bouc_wen_rate(p, z, rate)
            dy[2 * n + int(p[5])] = z_rate
            loss += p[0] * z * (rate - z_rate)
        elif law != SMOOTH_NONE:
            loss += _smooth_tension(m, e, rate, y) * rate
        dy[acc + term] += loss
    dy[acc] += dissipated
    dy[acc + 1] += power


@kernel
def jacobian(m, y, J):
    """J = d rhs / dy at y, nonlinear elements' tangents included: [[0, I], [-M^-1 Kt, -M^-1 Ct]]."""
    n = m.n
    J[:, :] = 0.0
    for i in range(n):
        J[i, n + i] = 1.0
        for k in range(m.a_ptr[i], m.a_ptr[i + 1]):
            J[n + i, m.a_idx[k]] = m.a_val[k]
    for e in range(len(m.el_law)):
        a, b = m.el_a[e], m.el_b[e]
        offset = 0 if m.el_law[e] == CUBIC_SPRING else n
        d = (y[offset + a] if a >= 0 else 0.0) - (y[offset + b] if b >= 0 else 0.0)
        slope = 3 * m.el_coef[e] * d * d if m.el_law[e] == CUBIC_SPRING else 2 * m.el_coef[e] * abs(d)
        for r in range(n):
            w = 0.0  # (M^-1[r, a] - M^-1[r, b]) slope, from M^-1's sparse rows
            for k in range(m.mi_ptr[r], m.mi_ptr[r + 1]):
                if m.mi_idx[k] == a:
                    w += m.mi_val[k]
                elif m.mi_idx[k] == b:
                    w -= m.mi_val[k]
            w *= slope
            if a >= 0:
                J[n + r, offset + a] -= w
            if b >= 0:
                J[n + r, offset + b] += w


@no_alloc
def state_jacobian(m, t, y, mid, rtol, atol, J, work, Jscratch, f0, arg, f1):
    """The Jacobian at (t, y) into J: the model's analytic one, or forward differences of a nonsmooth mode's
    right-hand side (its laws' internal variables and energy powers included); returns the right-hand sides it
    took."""
    if len(m.ns_belt) == 0:
        jacobian(m, y, J)
        return 0
    size = len(y)
    state_rhs(m, t, y, t >= mid, f0, work, Jscratch)
    for j in range(size):
        for i in range(size):
            arg[i] = y[i]
        step = 1.5e-8 * max(abs(y[j]), atol[j] / rtol)
        arg[j] += step
        state_rhs(m, t, arg, t >= mid, f1, work, Jscratch)
        for i in range(size):
            J[i, j] = (f1[i] - f0[i]) / step
    return size + 1


def work_size(m) -> int:
    """Scratch a right-hand side needs: n forces, E tensions, and the deepest expression's stack."""
    depths = [int(p[0]) for kind, p in zip(m.f_kind, m.f_par) if kind == EXPRESSION]
    return m.n + len(m.ns_belt) + max(depths, default=0) + 1


@inlined
def state_rhs_inlined(m, t, y, left, dy, work, J):
    """rhs for y = [x; v] (length 2n), or with the variational equation Phi' = J Phi appended (length
    2n + (2n)^2, Phi row-major) for a monodromy matrix; J is scratch of (2n, 2n). Inlined where it is called
    per stage (a call costs ~35 ns, three times the 1-DOF arithmetic); state_rhs is the same as a call."""
    size = 2 * m.n + m.ns_q + m.ns_acc
    rhs(m, t, y[:size], left, dy[:size], work)  # one inlined copy of rhs serves both cases
    if len(y) > size:
        _variational(m, y, dy, J)


@no_alloc
def _variational(m, y, dy, J):
    """dy's variational part: Phi' = J(y) Phi, with Phi row-major after the state in y."""
    size = 2 * m.n
    jacobian(m, y[:size], J)
    phi = y[size:].reshape((size, size))
    dphi = dy[size:].reshape((size, size))
    for i in range(size):
        for k in range(size):
            s = 0.0
            for q in range(size):
                s += J[i, q] * phi[q, k]
            dphi[i, k] = s


@no_alloc
def state_rhs(m, t, y, left, dy, work, J):
    """state_rhs_inlined as a function call, for the places where one more inlined copy is not worth its compile."""
    state_rhs_inlined(m, t, y, left, dy, work, J)
