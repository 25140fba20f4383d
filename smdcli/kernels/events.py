"""A nonsmooth scene's mode integrated by a compiled explicit Runge-Kutta pair until its first event.

The mode is a ModelArrays whose nonsmooth fields are filled (smdcli.kernels.arrays): the right-hand side then
carries the laws' internal variables and the energy terms' powers with the motion, so that the method's own
error control holds them. After every accepted step each guard is looked at on the step's dense output (its
ends and INTERIOR points between, so that a touch within a step is seen), the first crossing located on that
interpolant by Brent's method to rounding, and the run stops there; the decisions at the event (stick or slip,
impact, yield ...) are taken by the caller (smdcli.solvers.events.integrated), which starts the next mode. No
Python runs between two events.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.kernels.compiler import kernel, no_alloc
from smdcli.kernels.erk import (ACCEPTED, DOP853, ERROR_ORDER, NFEV, OK, STAGES, STEP_BUDGET, T_REACHED, assign,
                                attempt, initial_step, state_status)
from smdcli.kernels.guards import stop_at, watch_scratch, watch_step
from smdcli.kernels.rhs import state_rhs


@kernel
def integrate_mode(m, method, y, t0, bounds, mids, grid, k, rtol, atol, max_steps, bound, skip_t, skip_guard, out,
                   out_a, out_t, counts, floats, work, fixed_h):
    """Integrate the mode m from (t0, y) through the stretches between force discontinuities that end at bounds
    (mids: their midpoints, where forces turn to their left limits), restarting at each, and stopping at the
    mode's first guard crossing; y ends as the state where it stopped. Grid rows k.. before the stop (at it, where
    no event ends the run) are written: the state to out, the acceleration to out_a, the elements' tensions to
    out_t. skip_guard crossing again within 16 ulps of skip_t is the event just taken, read on the far side of its
    own rounding: not an event. Returns (status, the next row, the guard that fired or -1); floats[T_REACHED] is
    where it stopped. fixed_h > 0 takes steps of that size with no error control."""
    size = len(y)
    K = np.zeros((16, size))
    F = np.zeros((7, size))
    jwork = np.zeros((1, 1))
    arg, err, err3 = np.zeros(size), np.zeros(size), np.zeros(size)
    y_new, scale, dy = np.zeros(size), np.zeros(size), np.zeros(size)
    samples, rows, values, when, row = watch_scratch(m, size)
    Q = np.zeros((1, 1))  # Radau's interpolant: not this kernel's
    t = t0
    floats[T_REACHED] = t
    for stretch in range(len(bounds)):
        t_bound, mid = bounds[stretch], mids[stretch]
        if t >= t_bound:
            continue
        status, k, fired = _stretch(m, method, y, t, t_bound, mid, grid, k, rtol, atol, max_steps, bound, skip_t,
                                    skip_guard, out, out_a, out_t, counts, floats, work, fixed_h, K, F, Q, jwork, arg,
                                    err, err3, y_new, scale, dy, samples, rows, values, when, row)
        if status != OK:
            return status, k, fired
        t = t_bound
    return OK, k, -1


@no_alloc
def _stretch(m, method, y, t, t_bound, mid, grid, k, rtol, atol, max_steps, bound, skip_t, skip_guard, out, out_a,
             out_t, counts, floats, work, fixed_h, K, F, Q, jwork, arg, err, err3, y_new, scale, dy, samples, rows,
             values, when, row):
    """integrate_mode over one stretch between force discontinuities, from a fresh start at t."""
    n = m.n
    G = len(m.gd_el)
    S = STAGES[method]
    state_rhs(m, t, y, t >= mid, K[0], work, jwork)
    h_abs = fixed_h if fixed_h > 0 else initial_step(m, t, y, K[0], t_bound, ERROR_ORDER[method], rtol, atol, mid, work,
                                                     jwork, K[1], arg, scale)
    counts[NFEV] += 2
    while t < t_bound:
        status, t_new, h, h_abs = attempt(m, method, t, y, h_abs, t_bound, mid, rtol, atol, fixed_h, K, y_new, scale,
                                          err, err3, arg, work, jwork, counts, np.bool_(False))
        if status != OK:
            return status, k, -1
        counts[ACCEPTED] += 1
        if counts[ACCEPTED] > max_steps:
            return STEP_BUDGET, k, -1
        k_before = k
        k, t_stop, fired = watch_step(m, method, t, t_new, h, y, y_new, K, F, Q, grid, k, mid, work, jwork, arg, skip_t,
                                      skip_guard, samples, rows, values, when, row, dy, out, out_a, out_t)
        if method == DOP853 and (k > k_before or G > 0):
            counts[NFEV] += 3
        if fired >= 0:
            return stop_at(m, y, row, t_stop, bound, floats), k, fired
        assign(y, y_new)
        floats[T_REACHED] = t_new
        status = state_status(y[:2 * n], bound)
        if status != OK:
            return status, k, -1
        t = t_new
        assign(K[0], K[S])
    return OK, k, -1
