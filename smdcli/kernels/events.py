"""A nonsmooth scene's mode integrated by a compiled explicit Runge-Kutta pair until its first event.

The mode is a ModelArrays whose nonsmooth fields are filled (smdcli.kernels.arrays): the right-hand side then
carries the laws' internal variables and the energy terms' powers with the motion, so that the method's own
error control holds them. After every accepted step each guard is looked at on the step's dense output (its
ends and INTERIOR points between, so that a touch within a step is seen), the first crossing located on that
interpolant by Brent's method to rounding, and the run stops there; the decisions at the event (stick or slip,
impact, yield ...) are taken by the caller (smdcli.solvers.nonsmooth_ivp), which starts the next mode. No
Python runs between two events.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.kernels.arrays import GUARD_D, GUARD_INTERNAL, GUARD_RATE
from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import (ACCEPTED, DOP853, ERROR_ORDER, NFEV, OK, STAGES, STEP_BUDGET, T_REACHED, _dense,
                                assign, attempt, initial_step, state_status)
from smdcli.kernels.rhs import state_rhs

INTERIOR = 4  # interior points of each step where guards are looked at too (as smdcli.solvers.nonsmooth_ivp)
EVENT = 6  # a status beyond erk's: the run stopped at a guard's crossing
EPS = 2.220446049250313e-16


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
def _at(m, method, t_old, h, y_old, y_new, K, s, mid, work, jwork, arg, F, when, row, dy, g):
    """Guard g's value on the step's interpolant at time s (row: the interpolated state)."""
    when[0] = s
    _dense(m, method, t_old, h, y_old, y_new, K, when, 0, 1, row, mid, work, jwork, arg, F)
    state_rhs(m, s, row[0], s >= mid, dy, work, jwork)
    return guard_value(m, g, row[0], work)


@no_alloc
def _root(m, method, t_old, h, y_old, y_new, K, mid, work, jwork, arg, F, when, row, dy, g, a, b, fa, fb):
    """Brent's method (scipy's brentq) for guard g's crossing in [a, b] on the interpolant, to rounding: xtol
    2 eps (b - a), rtol 4 eps, as smdcli.solvers.piecewise.event_root."""
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
        fcur = _at(m, method, t_old, h, y_old, y_new, K, cur, mid, work, jwork, arg, F, when, row, dy, g)
    return cur


@kernel
def integrate_mode(m, method, y, t0, bounds, mids, grid, k, rtol, atol, max_steps, bound, skip_t, skip_guard, out,
                   out_a, out_t, counts, floats, work):
    """Integrate the mode m from (t0, y) through the stretches between force discontinuities that end at bounds
    (mids: their midpoints, where forces turn to their left limits), restarting at each, and stopping at the
    mode's first guard crossing; y ends as the state where it stopped. Grid rows k.. before the stop (at it, where
    no event ends the run) are written: the state to out, the acceleration to out_a, the elements' tensions to out_t. skip_guard crossing again within 16 ulps
    of skip_t is the event just taken, read on the far side of its own rounding: not an event. Returns (status,
    the next row, the guard that fired or -1); floats[T_REACHED] is where it stopped."""
    size = len(y)
    G = len(m.gd_el)
    K = np.zeros((16, size))
    F = np.zeros((7, size))
    jwork = np.zeros((1, 1))
    arg, err, err3 = np.zeros(size), np.zeros(size), np.zeros(size)
    y_new, scale, dy = np.zeros(size), np.zeros(size), np.zeros(size)
    samples = np.zeros(INTERIOR + 2)
    rows = np.zeros((INTERIOR + 2, size))
    values = np.zeros((INTERIOR + 2, max(G, 1)))
    when, row = np.zeros(1), np.zeros((1, size))
    t = t0
    floats[T_REACHED] = t
    for stretch in range(len(bounds)):
        t_bound, mid = bounds[stretch], mids[stretch]
        if t >= t_bound:
            continue
        status, k, fired = _stretch(m, method, y, t, t_bound, mid, grid, k, rtol, atol, max_steps, bound, skip_t,
                                    skip_guard, out, out_a, out_t, counts, floats, work, K, F, jwork, arg, err, err3,
                                    y_new, scale, dy, samples, rows, values, when, row)
        if status != OK:
            return status, k, fired
        t = t_bound
    return OK, k, -1


@no_alloc
def _stretch(m, method, y, t, t_bound, mid, grid, k, rtol, atol, max_steps, bound, skip_t, skip_guard, out, out_a,
             out_t, counts, floats, work, K, F, jwork, arg, err, err3, y_new, scale, dy, samples, rows, values, when,
             row):
    """integrate_mode over one stretch between force discontinuities, from a fresh start at t."""
    n = m.n
    G = len(m.gd_el)
    S = STAGES[method]
    state_rhs(m, t, y, t >= mid, K[0], work, jwork)
    h_abs = initial_step(m, t, y, K[0], t_bound, ERROR_ORDER[method], rtol, atol, mid, work, jwork, K[1], arg, scale)
    counts[NFEV] += 2
    while t < t_bound:
        status, t_new, h, h_abs = attempt(m, method, t, y, h_abs, t_bound, mid, rtol, atol, 0.0, K, y_new, scale, err,
                                          err3, arg, work, jwork, counts)
        if status != OK:
            return status, k, -1
        counts[ACCEPTED] += 1
        if counts[ACCEPTED] > max_steps:
            return STEP_BUDGET, k, -1
        t_stop, fired = t_new, -1
        if G > 0:
            for i in range(INTERIOR + 2):
                samples[i] = t + h * i / (INTERIOR + 1)
            samples[INTERIOR + 1] = t_new
            _dense(m, method, t, h, y, y_new, K, samples, 0, INTERIOR + 2, rows, mid, work, jwork, arg, F)
            for i in range(INTERIOR + 2):
                state_rhs(m, samples[i], rows[i], samples[i] >= mid, dy, work, jwork)
                for g in range(G):
                    values[i, g] = guard_value(m, g, rows[i], work)
            for g in range(G):
                s = m.gd_dir[g]
                for i in range(INTERIOR + 1):
                    if s * values[i, g] < 0 <= s * values[i + 1, g]:
                        lo, hi = samples[i], samples[i + 1]
                        if values[i + 1, g] == 0:
                            root = hi
                        else:
                            root = _root(m, method, t, h, y, y_new, K, mid, work, jwork, arg, F, when, row, dy, g, lo,
                                         hi, values[i, g], values[i + 1, g])
                        if g == skip_guard and root - skip_t <= 16 * np.spacing(max(abs(skip_t), 1e-300)):
                            continue
                        if fired < 0 or root < t_stop:
                            t_stop, fired = root, g
                        break
        wrote = False
        last = k
        while last < len(grid) and grid[last] <= t_stop and (fired < 0 or grid[last] < t_stop):
            last += 1
        if last > k:
            wrote = True
            _dense(m, method, t, h, y, y_new, K, grid, k, last, out, mid, work, jwork, arg, F)
            for r in range(k, last):
                state_rhs(m, grid[r], out[r], grid[r] >= mid, dy, work, jwork)
                for i in range(n):
                    out_a[r, i] = dy[n + i]
                for e in range(len(m.ns_belt)):
                    out_t[r, e] = work[n + e]
            k = last
        if method == DOP853 and (wrote or G > 0):
            counts[NFEV] += 3
        if fired >= 0:
            when[0] = t_stop
            _dense(m, method, t, h, y, y_new, K, when, 0, 1, row, mid, work, jwork, arg, F)
            assign(y, row[0])
        else:
            assign(y, y_new)
        floats[T_REACHED] = t_stop
        status = state_status(y[:2 * n], bound)
        if status != OK:
            return status, k, -1
        if fired >= 0:
            return EVENT, k, fired
        t = t_new
        assign(K[0], K[S])
    return OK, k, -1
