"""Compiled forces, right-hand side and Jacobian of M x'' + C x' + K x + f_nl(x, x') = B u(t).

Every function reads a ModelArrays (smdcli.kernels.arrays); values match smdcli.model.forcing's signals,
left limits included (`left` is true in the second half of a stretch between force discontinuities, so
a jump at its end never leaks in).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.elements.base import SMOOTH_BOUC_WEN, SMOOTH_NONE, SMOOTH_STRIBECK, SMOOTH_TANH
from smdcli.expression import OP_ADD, OP_CONST, OP_DIV, OP_FUNCTION, OP_MUL, OP_NEG, OP_POW, OP_SUB, OP_T
from smdcli.kernels.arrays import (CHIRP, CONSTANT, COSINE, CUBIC_SPRING, EXPRESSION, FOURIER_SQUARE, PULSE, SINE,
                                   SQUARE, STEP, TABLE_LINEAR, TABLE_PREVIOUS)
from smdcli.kernels.compiler import inlined, kernel, no_alloc

# The function opcodes as plain ints, which the compiled interpreter needs (it cannot read the dict).
(OP_SIN, OP_COS, OP_TAN, OP_EXP, OP_LOG, OP_SQRT, OP_ABS, OP_SIGN, OP_TANH,
 OP_HEAVISIDE) = (OP_FUNCTION[name] for name in ("sin", "cos", "tan", "exp", "log", "sqrt", "abs", "sign", "tanh",
                                                 "heaviside"))

EDGE_SNAP = 1e-9  # as smdcli.model.forcing._EDGE_SNAP: a phase within this of a square wave's edge is on it


@kernel
def _search(times, t, right):
    """numpy.searchsorted(times, t, side='right' if right else 'left')."""
    lo, hi = 0, len(times)
    while lo < hi:
        mid = (lo + hi) // 2
        if times[mid] < t or (right and times[mid] == t):
            lo = mid + 1
        else:
            hi = mid
    return lo


@kernel
def _table(times, values, t, previous, left):
    """A table force: first-order hold (numpy.interp, ends held) or previous value. A last time given twice is a jump
    there (a record that ends: Table.kernel_knots), its left limit the first copy's value."""
    count = len(times)
    if previous:
        i = _search(times, t, not left) - 1
        return values[max(i, 0)]
    if t <= times[0]:
        return values[0]
    if t > times[count - 1] or (t == times[count - 1] and not left):
        return values[count - 1]
    i = _search(times, t, not left) - 1
    s = (t - times[i]) / (times[i + 1] - times[i])
    return values[i] + s * (values[i + 1] - values[i])


@kernel
def _expression(codes, constants, t, stack):
    """Run a postfix program (smdcli.expression's opcodes) at t; stack is scratch as deep as the program."""
    top = -1
    c = 0
    for op in codes:
        if op == OP_CONST:
            top += 1
            stack[top] = constants[c]
            c += 1
        elif op == OP_T:
            top += 1
            stack[top] = t
        elif op <= OP_POW:
            b = stack[top]
            top -= 1
            a = stack[top]
            if op == OP_ADD:
                stack[top] = a + b
            elif op == OP_SUB:
                stack[top] = a - b
            elif op == OP_MUL:
                stack[top] = a * b
            elif op == OP_DIV:
                stack[top] = a / b
            else:
                stack[top] = np.power(a, b)
        elif op == OP_NEG:
            stack[top] = -stack[top]
        else:
            x = stack[top]
            if op == OP_SIN:
                x = np.sin(x)
            elif op == OP_COS:
                x = np.cos(x)
            elif op == OP_TAN:
                x = np.tan(x)
            elif op == OP_EXP:
                x = np.exp(x)
            elif op == OP_LOG:
                x = np.log(x)
            elif op == OP_SQRT:
                x = np.sqrt(x)
            elif op == OP_ABS:
                x = abs(x)
            elif op == OP_SIGN:
                x = np.sign(x)
            elif op == OP_TANH:
                x = np.tanh(x)
            else:  # heaviside
                x = 1.0 if x >= 0 else 0.0
            stack[top] = x
    return stack[0]


@inlined
def force_value(m, j, t, left, stack):
    """Force j of model arrays m at t (its left limit if `left`); stack is scratch for expressions."""
    kind = m.f_kind[j]
    p = m.f_par[j]
    data = m.f_data[m.f_ptr[j]:m.f_ptr[j + 1]]
    if kind == CONSTANT:
        return p[0]
    if kind == STEP:
        on = t > p[1] if left else t >= p[1]
        return p[0] if on else 0.0
    if kind == PULSE:
        on = (t > p[1] and t <= p[2]) if left else (t >= p[1] and t < p[2])
        return p[0] if on else 0.0
    if kind == SINE:
        return p[0] * math.sin(p[1] * t + p[2])
    if kind == COSINE:
        return p[0] * math.cos(p[1] * t + p[2])
    if kind == SQUARE:
        phase = (t - p[3]) / p[1]
        phase = phase - math.floor(phase)
        if phase > 1 - EDGE_SNAP:
            phase = 0.0
        if abs(phase - p[2]) < EDGE_SNAP:
            phase = p[2]
        high = (phase > 0 and phase <= p[2]) if left else phase < p[2]
        return p[0] if high else -p[0]
    if kind == FOURIER_SQUARE:
        terms = len(data) // 2
        total = 0.0
        for i in range(terms):
            total += data[terms + i] * math.sin(data[i] * p[0] * (t - p[1]) + p[2])
        return total
    if kind == CHIRP:
        return p[0] * math.sin(2 * math.pi * (p[1] * t + 0.5 * p[2] * t * t) + p[3])
    if kind == TABLE_LINEAR or kind == TABLE_PREVIOUS:
        half = len(data) // 2
        return _table(data[:half], data[half:], t, kind == TABLE_PREVIOUS, left)
    if kind == EXPRESSION:  # its edges are first floats past a crossing: the float before gives the left limit
        program = m.f_code[m.f_cptr[j]:m.f_cptr[j + 1]]
        if left:
            before = _expression(program, data, np.nextafter(t, -np.inf), stack)
            if math.isfinite(before):
                return before
        return _expression(program, data, t, stack)
    return math.nan


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
        loss = (m.ns_pd[e] * rate + m.ns_pc[e]) * rate
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
            w = ((m.minv[r, a] if a >= 0 else 0.0) - (m.minv[r, b] if b >= 0 else 0.0)) * slope
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
