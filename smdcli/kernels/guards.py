"""The guards of a nonsmooth scene's mode, watched on a compiled integrator's step: where the first one crosses its
level, located on the step's interpolant to rounding, and the output rows written up to there.

Every integrator that runs modes (the explicit pairs in events.py, radau.py, bdf.py, stiff.py) hands its step
over as the same arguments (method, t_old, h, y_old, y_new, K, F, Q), the interpolant named by `method`:

- RK23, RK45, DOP853: the pair's own (K its stages, F scratch: erk._dense);
- RADAU: the collocation polynomial y_old + Q [x, x^2, x^3], x = (t - t_old) / h;
- BDF: the difference polynomial of the difference array K, about F[0] = (t, h, order) (scipy's BdfDenseOutput);
- ROSENBROCK: ode23s's free interpolant y_old + h (a(x) K[0] + b(x) K[1]) from its stages k1, k2;
- HERMITE: the cubic Hermite polynomial through (y_old, K[0] = f) and (y_new, K[1] = f_new) (the trapezoidal rule and TR-BDF2).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.kernels.arrays import GUARD_D, GUARD_INTERNAL, GUARD_RATE, INTERIOR
from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import _dense, state_status
from smdcli.kernels.fixed import _hermite
from smdcli.kernels.rhs import state_rhs
from smdcli.kernels.tableaus import ROS_D

RADAU, BDF, ROSENBROCK, HERMITE = 3, 4, 5, 6  # interpolants beyond erk's method ids (RK23, RK45, DOP853)
EVENT = 6  # a status beyond erk's: the run stopped at a guard's crossing
EPS = 2.220446049250313e-16


@kernel
def watch_scratch(m, size):
    """What watch_step needs beside a state of `size`: the sample times, their states, the guards' values there
    (and in columns G.. their slopes), and one time and state for Brent's method."""
    G = len(m.gd_el)
    return (np.zeros(INTERIOR + 2), np.zeros((INTERIOR + 2, size)), np.zeros((INTERIOR + 2, max(2 * G, 1))),
            np.zeros(1), np.zeros((1, size)))


SKIP_EVERY_KINK = -2  # skip_guard: every guard crossing at skip_t is a kink just left (_fired_again)

@no_alloc
def interpolate(m, method, t_old, h, y_old, y_new, K, F, Q, times, k, j, out, mid, work, jwork, arg):
    """Rows k..j-1 of out at `times` from the step's interpolant."""
    size = len(y_old)
    if method == RADAU:
        for row in range(k, j):
            x = (times[row] - t_old) / h
            for i in range(size):
                out[row, i] = y_old[i] + Q[i, 0] * x + Q[i, 1] * x * x + Q[i, 2] * x * x * x
        return
    if method == BDF:
        t_ref, h_ref, order = F[0, 0], F[0, 1], int(F[0, 2])
        for row in range(k, j):
            for i in range(size):
                value = K[0, i]
                p = 1.0
                for q in range(order):
                    p *= (times[row] - (t_ref - h_ref * q)) / (h_ref * (1 + q))
                    value += K[q + 1, i] * p
                out[row, i] = value
        return
    if method == ROSENBROCK:
        for row in range(k, j):
            s = (times[row] - t_old) / h
            a = s * (1 - s) / (1 - 2 * ROS_D)
            b = s * (s - 2 * ROS_D) / (1 - 2 * ROS_D)
            for i in range(size):
                out[row, i] = y_old[i] + h * (a * K[0, i] + b * K[1, i])
        return
    if method == HERMITE:
        _hermite(t_old, h, y_old, K[0], y_new, K[1], times, k, j, out)
        return
    _dense(m, method, t_old, h, y_old, y_new, K, times, k, j, out, mid, work, jwork, arg, F)


@no_alloc
def guard_value(m, g, y, work):
    """Guard g's quantity less its level at y; work holds the tensions of the right-hand side just taken at y."""
    e = m.gd_el[g]
    quantity = m.gd_qty[g]
    if quantity == GUARD_INTERNAL:
        return y[2 * m.n + int(m.ns_par[e, 5])] - m.gd_level[g]
    if quantity == GUARD_D or quantity == GUARD_RATE:
        value = 0.0 if quantity == GUARD_D else m.ns_belt[e]
        offset = 0 if quantity == GUARD_D else m.n
        for i in range(m.n):
            value += m.ns_R[e, i] * y[offset + i]
        return value - m.gd_level[g]
    return work[m.n + e] - m.gd_level[g]


@no_alloc
def _rounding(value, level):
    """How far from its level a guard's value (quantity less level) is rounding of it: 64 ulps of what it sums,
    as smdcli.solvers.events.scene.at_level."""
    return 64 * EPS * (abs(value + level) + abs(level))


@no_alloc
def _fired_again(g, root, skip_guard, skip_t):
    """Whether guard g's root is the event just taken (skip_guard at skip_t), read again on the far side of its
    own rounding: within 16 ulps of its time. skip_guard = SKIP_EVERY_KINK: every guard is, there (smooth laws'
    kinks left at one instant, several at once: a Bouc-Wen spring at rest, d' and z both 0)."""
    return (g == skip_guard or skip_guard == SKIP_EVERY_KINK) and \
        root - skip_t <= 16 * np.spacing(max(abs(skip_t), 1e-300))


@no_alloc
def guard_slope(m, g, y, dy):
    """The rate of guard g's quantity at y (dy: y' there) where it is d or d' (their rates d' and d''); nan for a
    held element's tension or an internal variable, whose touches within a step are left to the samples."""
    quantity = m.gd_qty[g]
    if quantity != GUARD_D and quantity != GUARD_RATE:
        return np.nan
    e = m.gd_el[g]
    value = 0.0
    for i in range(m.n):
        value += m.ns_R[e, i] * (y[m.n + i] if quantity == GUARD_D else dy[m.n + i])
    return value


@no_alloc
def _slope_at(m, method, t_old, h, y_old, y_new, K, F, Q, s, mid, work, jwork, arg, when, row, dy, g):
    """Guard g's slope on the step's interpolant at time s."""
    _sample(m, method, t_old, h, y_old, y_new, K, F, Q, s, mid, work, jwork, arg, when, row, dy)
    return guard_slope(m, g, row[0], dy)


@no_alloc
def _touch(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g, lo, hi, f_lo,
           slope_lo, slope_hi):
    """Where guard g, below its level at both ends of [lo, hi] and turning there (rising at lo, falling at hi),
    reaches its level at the top of its excursion (a light rebound landing again before the next sample); inf if
    the top stays below. The top is the slope's root (bisection with a secant guess), as the exact solver's
    check finds it."""
    s = m.gd_dir[g]
    a, b, fa, fb = lo, hi, s * slope_lo, s * slope_hi
    for _ in range(200):  # bisection with a secant guess: the slope is smooth and changes sign once here
        if b - a <= 4 * EPS * max(abs(a), abs(b)):
            break
        c = a + (b - a) * fa / (fa - fb)
        if not a < c < b:
            c = 0.5 * (a + b)
        fc = s * _slope_at(m, method, t_old, h, y_old, y_new, K, F, Q, c, mid, work, jwork, arg, when, row, dy, g)
        if fc > 0:
            a, fa = c, fc
        else:
            b, fb = c, fc
        if abs(fc) == 0 or b - a < 0.25 * (hi - lo) * 2.0 ** -40:
            break
    top = 0.5 * (a + b)
    f_top = _at(m, method, t_old, h, y_old, y_new, K, F, Q, top, mid, work, jwork, arg, when, row, dy, g)
    if s * f_top < 0:
        return np.inf
    if f_top == 0:
        return top
    return _root(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g, lo, top, f_lo,
                 f_top)


@no_alloc
def _sample(m, method, t_old, h, y_old, y_new, K, F, Q, s, mid, work, jwork, arg, when, row, dy):
    """The step's interpolant at time s into row[0], its right-hand side into dy (and the tensions into work)."""
    when[0] = s
    interpolate(m, method, t_old, h, y_old, y_new, K, F, Q, when, np.int64(0), np.int64(1), row, mid, work, jwork, arg)
    state_rhs(m, s, row[0], s >= mid, dy, work, jwork)


@no_alloc
def _at(m, method, t_old, h, y_old, y_new, K, F, Q, s, mid, work, jwork, arg, when, row, dy, g):
    """Guard g's value on the step's interpolant at time s (row: the interpolated state)."""
    _sample(m, method, t_old, h, y_old, y_new, K, F, Q, s, mid, work, jwork, arg, when, row, dy)
    return guard_value(m, g, row[0], work)


@no_alloc
def _root(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g, a, b, fa, fb):
    """Brent's method (scipy's brentq) for guard g's crossing in [a, b] on the interpolant, to rounding: xtol
    2 eps (b - a), rtol 4 eps, as smdcli.solvers.events.scene.event_root."""
    xtol = 2 * EPS * (b - a)
    rtol = 4 * EPS
    pre, cur = a, b
    fpre, fcur = fa, fb
    blk, fblk, spre, scur = 0.0, 0.0, 0.0, 0.0
    for _ in range(400):
        if fpre != 0 and fcur != 0 and (fpre > 0) != (fcur > 0):
            blk, fblk = pre, fpre
            spre = scur = cur - pre
        if abs(fblk) < abs(fcur):
            pre, cur, blk = cur, blk, cur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(cur)) / 2
        sbis = (blk - cur) / 2
        if fcur == 0 or abs(sbis) < delta:
            return cur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if pre == blk:
                stry = -fcur * (cur - pre) / (fcur - fpre)
            else:
                dpre = (fpre - fcur) / (pre - cur)
                dblk = (fblk - fcur) / (blk - cur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2 * abs(stry) < min(abs(spre), 3 * abs(sbis) - delta):
                spre, scur = scur, stry
            else:
                spre, scur = sbis, sbis
        else:
            spre, scur = sbis, sbis
        pre, fpre = cur, fcur
        if abs(scur) > delta:
            cur += scur
        else:
            cur += delta if sbis > 0 else -delta
        fcur = _at(m, method, t_old, h, y_old, y_new, K, F, Q, cur, mid, work, jwork, arg, when, row, dy, g)
    return cur


@no_alloc
def first_crossing(m, method, t_old, t_new, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, skip_t, skip_guard,
                   samples, rows, values, when, row, dy):
    """(time, guard) of the first guard crossing in the step (t_old, t_new], or (t_new, -1) if none.
    skip_guard crossing again within 16 ulps of skip_t is the event just taken, read on the far side of its own
    rounding: not an event."""
    t_stop, fired = t_new, -1
    G = len(m.gd_el)
    if G == 0:
        return t_stop, fired
    for i in range(INTERIOR + 2):
        samples[i] = t_old + h * i / (INTERIOR + 1)
    interpolate(m, method, t_old, h, y_old, y_new, K, F, Q, samples, np.int64(0), np.int64(INTERIOR + 1), rows, mid,
                work, jwork, arg)
    for i in range(len(y_new)):
        rows[INTERIOR + 1, i] = y_new[i]
    samples[INTERIOR + 1] = t_new
    for i in range(INTERIOR + 2):
        state_rhs(m, samples[i], rows[i], samples[i] >= mid, dy, work, jwork)
        for g in range(G):
            values[i, g] = guard_value(m, g, rows[i], work)
            values[i, G + g] = guard_slope(m, g, rows[i], dy)
    for g in range(G):
        s = m.gd_dir[g]
        level = m.gd_level[g]
        root = np.inf
        for i in range(INTERIOR + 1):
            if s * values[i, g] < 0 <= s * values[i + 1, g]:
                lo, hi = samples[i], samples[i + 1]
                if values[i + 1, g] == 0:
                    root = hi
                else:
                    root = _root(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g,
                                 lo, hi, values[i, g], values[i + 1, g])
                if _fired_again(g, root, skip_guard, skip_t):
                    root = np.inf
                    continue
                break
            if s * values[i, g] < -_rounding(values[i, g], level) and s * values[i + 1, g] < 0 \
                    and s * values[i, G + g] > 0 > s * values[i + 1, G + g]:  # a touch inside, not one at its level
                root = _touch(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g,
                              samples[i], samples[i + 1], values[i, g], values[i, G + g], values[i + 1, G + g])
                if _fired_again(g, root, skip_guard, skip_t):
                    root = np.inf
                if root < np.inf:
                    break
        # at its level to the rounding of its value, and of the time of the event that started the step (another
        # guard's on the same quantity: a spring yielding where a stop is, their levels apart by rounding)
        slope = values[0, G + g] if values[0, G + g] == values[0, G + g] else (values[1, g] - values[0, g]) / (
            samples[1] - samples[0])
        at = _rounding(values[0, g], level) + abs(slope) * 16 * np.spacing(abs(t_old))
        if root == np.inf and abs(values[0, g]) <= at and s * values[1, g] >= 0:
            # a kink's dip must be deeper than the interpolant's rounding of its quantity over the step: a kink just
            # taken whose quantity is flat there (a mass at rest until a force reaches it through two springs, v ~
            # t^3) was taken again at each of thousands of such dips, 4.5e-16 s apart; a contact's is any dip (a
            # rebound that rises less than rounding still lands)
            noise = 0.0
            if m.gd_kink[g]:
                for i in range(INTERIOR + 2):
                    noise = max(noise, _rounding(values[i, g], level))
            root = _return(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g,
                           samples[1], values[1, g], noise)
            if _fired_again(g, root, skip_guard, skip_t):
                root = np.inf
        if root < t_stop or (fired < 0 and root <= t_new):
            t_stop, fired = root, g
    return t_stop, fired


@no_alloc
def _return(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g, hi, f_hi, noise):
    """Where guard g, at its level at t_old and past it again at hi, comes back to it after a dip below it too
    short for the samples to see (a light rebound landing again, a spring unloading and yielding again): the dip
    found by halving towards t_old, then the crossing located. If it never went below, it went on past its level
    from t_old: an event there (a stop met again at rest while another contact bounced); inf where it only stays
    at its level to rounding (a spring on its yield surface held by a stuck contact). noise: how far below its
    level the interpolant's rounding puts it (a dip no deeper is none)."""
    s = m.gd_dir[g]
    tau = hi - t_old
    for _ in range(60):
        tau *= 0.5
        value = _at(m, method, t_old, h, y_old, y_new, K, F, Q, t_old + tau, mid, work, jwork, arg, when, row, dy, g)
        if s * value < -noise:
            if f_hi == 0:
                return hi
            return _root(m, method, t_old, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, when, row, dy, g,
                         t_old + tau, hi, value, f_hi)
    return t_old if s * f_hi > _rounding(f_hi, m.gd_level[g]) else np.inf


@no_alloc
def write_rows(m, method, t_old, h, y_old, y_new, K, F, Q, grid, k, t_stop, fired, out, out_a, out_t, mid, work,
               jwork, arg, dy):
    """Rows k.. of the grid up to t_stop (before it where an event ends the step) from the interpolant, with each
    row's acceleration and element tensions where the model is a mode; returns the next row."""
    last = k
    while last < len(grid) and grid[last] <= t_stop and (fired < 0 or grid[last] < t_stop):
        last += 1
    if last == k:
        return k
    interpolate(m, method, t_old, h, y_old, y_new, K, F, Q, grid, k, last, out, mid, work, jwork, arg)
    n = m.n
    if len(m.ns_belt) > 0:
        for r in range(k, last):
            state_rhs(m, grid[r], out[r], grid[r] >= mid, dy, work, jwork)
            for i in range(n):
                out_a[r, i] = dy[n + i]
            for e in range(len(m.ns_belt)):
                out_t[r, e] = work[n + e]
    return last


@no_alloc
def watch_step(m, method, t_old, t_new, h, y_old, y_new, K, F, Q, grid, k, mid, work, jwork, arg, skip_t, skip_guard,
               samples, rows, values, when, row, dy, out, out_a, out_t):
    """An accepted step's guards watched and its rows written: (next row, where it stops, the guard that fired or
    -1); where one fired, row[0] holds the state there."""
    t_stop, fired = first_crossing(m, method, t_old, t_new, h, y_old, y_new, K, F, Q, mid, work, jwork, arg, skip_t,
                                   skip_guard, samples, rows, values, when, row, dy)
    k = write_rows(m, method, t_old, h, y_old, y_new, K, F, Q, grid, k, t_stop, fired, out, out_a, out_t, mid, work,
                   jwork, arg, dy)
    if fired >= 0:
        when[0] = t_stop
        interpolate(m, method, t_old, h, y_old, y_new, K, F, Q, when, np.int64(0), np.int64(1), row, mid, work, jwork,
                    arg)
    return k, t_stop, fired


@no_alloc
def stop_at(m, y, row, t_stop, bound, floats):
    """The run stopped at an event: y set to the state there (row[0]), the time reached recorded; EVENT, or the
    state's failure status (erk's) where it is past the bound or not finite."""
    for i in range(len(y)):
        y[i] = row[0, i]
    floats[0] = t_stop
    status = state_status(y[:2 * m.n], bound)
    return EVENT if status == 0 else status
