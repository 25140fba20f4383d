"""Compiled force shapes: each force row's value (its left limit too) and Taylor series, as the shapes in
smdcli.shapes define them. This is the one kernel file that names the shapes: a new shape's row kind is read here.

`left` is true in the second half of a stretch between force discontinuities, so a jump at its end never leaks
in. Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.expression import OP_ADD, OP_CONST, OP_DIV, OP_FUNCTION, OP_MUL, OP_NEG, OP_POW, OP_SUB, OP_T
from smdcli.kernels.compiler import inlined, kernel, no_alloc
from smdcli.shapes.base import EDGE_SNAP
from smdcli.shapes.chirp import CHIRP
from smdcli.shapes.constant import CONSTANT
from smdcli.shapes.expression import EXPRESSION
from smdcli.shapes.fourier_square import FOURIER_SQUARE
from smdcli.shapes.harmonic import COSINE, SINE
from smdcli.shapes.pulse import PULSE
from smdcli.shapes.square import SQUARE
from smdcli.shapes.step import STEP
from smdcli.shapes.table import TABLE_LINEAR, TABLE_PREVIOUS

# The function opcodes as plain ints, which the compiled interpreter needs (it cannot read the dict).
(OP_SIN, OP_COS, OP_TAN, OP_EXP, OP_LOG, OP_SQRT, OP_ABS, OP_SIGN, OP_TANH,
 OP_HEAVISIDE) = (OP_FUNCTION[name] for name in ("sin", "cos", "tan", "exp", "log", "sqrt", "abs", "sign", "tanh",
                                                 "heaviside"))

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
def _pulse(data, tau):
    """A pulse inside its window: c + a sin(w tau + q pi/2), data = (c, a, w, q), whole quarter turns exact."""
    x = data[2] * tau
    q = int(data[3])
    wave = math.sin(x) if q == 0 else math.cos(x) if q == 1 else -math.sin(x) if q == 2 else -math.cos(x)
    return data[0] + data[1] * wave


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
    if kind == PULSE:  # c + a sin(w tau + q pi/2) in [t0, t_end), data = (c, a, w, q)
        on = (t > p[0] and t <= p[1]) if left else (t >= p[0] and t < p[1])
        return _pulse(data, t - p[0]) if on else 0.0
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


@no_alloc
def _harmonic(amplitude, omega, phase, cosine, p, column, series):
    """Taylor coefficients of amplitude sin(phase + omega tau) (cos if cosine) about tau = 0 into series[:, column]."""
    s, c = math.sin(phase), math.cos(phase)
    cycle = (c, -s, -c, s) if cosine else (s, c, -s, -c)
    scale = amplitude
    for k in range(p + 1):
        series[k, column] += scale * cycle[k % 4]
        scale *= omega / (k + 1)


@no_alloc
def force_series(m, t, ta, mid, p, series, stack):
    """Each force's Taylor coefficients about t (in a stretch [ta, tb) between discontinuities, mid its middle);
    stack is force_value's scratch."""
    series[:, :] = 0.0
    for j in range(len(m.f_kind)):
        kind = m.f_kind[j]
        q = m.f_par[j]
        if kind == SINE or kind == COSINE:
            _harmonic(q[0], q[1], q[1] * t + q[2], kind == COSINE, p, j, series)
        elif kind == FOURIER_SQUARE:
            data = m.f_data[m.f_ptr[j]:m.f_ptr[j + 1]]
            terms = len(data) // 2
            for i in range(terms):
                omega = data[i] * q[0]
                _harmonic(data[terms + i], omega, omega * (t - q[1]) + q[2], np.bool_(False), p, j, series)
        elif kind == TABLE_LINEAR:  # a line between knots (they are discontinuities of its slope)
            series[0, j] = force_value(m, j, t, t >= mid, stack)
            if p >= 1 and mid > ta:
                right = np.bool_(False)  # a bool, not a literal False: one compile of the table's lookup
                series[1, j] = (force_value(m, j, mid, right, stack) - force_value(m, j, ta, right, stack)) / (mid - ta)
        elif kind == PULSE:
            if mid >= q[0] and mid < q[1]:  # inside its window the stretch is one harmonic and a constant
                data = m.f_data[m.f_ptr[j]:m.f_ptr[j + 1]]
                series[0, j] += data[0]
                _harmonic(data[1], data[2], data[2] * (t - q[0]) + data[3] * 0.5 * math.pi, np.bool_(False), p, j,
                          series)
        else:  # constant on the stretch, its value in the middle (Taylor.refuse: the shapes without series)
            series[0, j] = force_value(m, j, mid, np.bool_(False), stack)
