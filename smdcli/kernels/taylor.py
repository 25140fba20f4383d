"""A compiled Taylor series integrator for smooth scenes whose nonlinearities are polynomials.

Between two force discontinuities and two velocity reversals of its quadratic dampers, the motion of
M x'' + C x' + K x + f_nl(x, x') = B u(t) is analytic and its Taylor coefficients follow from a recurrence:
x_(k+1) = v_k / (k + 1), v_(k+1) = (M^-1 (u_k - f_k) - M^-1 K x_k - M^-1 C v_k) / (k + 1), where u_k are the
forces' coefficients (closed forms for sines and cosines, a constant or a line between a table's knots) and
f_k the elements' (a cubic spring's k3 d^3 and a quadratic damper's c s d'^2, s the sign of d' on the step,
by Cauchy products). One order costs one banded or sparse product (diagonals), about a right-hand side; a
step sums the series to order p at a step where its last two terms fall under the tolerance (Jorba and Zou,
2005), so no try is rejected, the output rows are the polynomial evaluated (no interpolant to build) and a
damper's reversal is the root of its velocity's polynomial, where the step ends.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from smdcli.kernels.arrays import CUBIC_SPRING
from smdcli.kernels.compiler import inlined, kernel, no_alloc
from smdcli.kernels.diagonals import banded_rows, diagonals, tridiagonal_rows
from smdcli.kernels.erk import (ACCEPTED, NFEV, NOT_FINITE, OK, STEP_BUDGET, STIFF, T_REACHED, TOO_SMALL_STEP,
                                WATCH_WINDOW, held_by_stability, linear_norms, relative, rows_through, state_status)
from smdcli.kernels.forces import force_series
from smdcli.kernels.series_rows import OUTPUT_SHARE, ROWS, acceleration_series, emit, order_sizes, summed, widen
from smdcli.kernels.taylor_spans import active_dofs, coupling_orders, loaded_dofs, terms_span

SAFETY = 0.9
EXTREMES = 5  # floats[5:9], after erk's: the least and largest x the rows hold, then v's
FLOATS = EXTREMES + 4
NEGLIGIBLE = 1e-6  # of the step's tolerance: a DOF whose x and v stay under it has not been reached yet
SAMPLES = 4  # points of each step where a damper's velocity polynomial is checked for a reversal


@no_alloc
def direction(D, e, k, scale_v, h_last):
    """The sign of quadratic damper e's d' on the step, from its series' terms 0..k: d' itself, unless it is within
    rounding of zero (1e-12 of the running peak speed scale_v) or reverses within a millionth of the last step
    h_last (a step that ended at a reversal leaves d' there, on either side); then its first term that is not
    zero. 0.0 while all are."""
    r0, r1 = D[0, e], D[1, e]
    if abs(r0) > 1e-12 * scale_v and not (r0 * r1 < 0 and abs(r0) < 1e-6 * abs(r1) * h_last):
        return 1.0 if r0 > 0 else -1.0
    for j in range(1, k + 1):
        if D[j, e] != 0.0:
            return 1.0 if D[j, e] > 0 else -1.0
    return 0.0


@no_alloc
def coefficients(m, band, spans, minv_diagonal, p, Y, U, D, D2, sign, scale_v, h_last, work, first, last, width,
                 orders):
    """Orders 1..p of the state's series Y = [x, v] (order 0 given), from the forces' series U; band, spans and
    minv_diagonal are the linear rows as diagonals (empty: the CSR rows); D and D2 hold each element's d (or d')
    and d^2 series, sign each quadratic damper's sign of d' on the step (direction); h_last is the last step; work
    is scratch of n. Order k is worked out only where it can be other than zero, terms_span(first, last, k, width,
    orders, n): order 0 and the loads are zero outside DOFs first..last-1 (active_dofs); elsewhere Y's terms stay the
    zeros they are."""
    n = m.n
    E = len(m.el_law)
    everywhere = terms_span(first, last, 1, width, orders, n) == (0, n)  # the common case, its loops' bounds known
    for e in range(E):
        sign[e] = 0.0
    for i in range(n):
        work[i] = 0.0
    for k in range(p):  # work holds the forces on DOFs of an order, and is zero again after it
        ground = 0.0
        for j in range(len(m.f_kind)):
            if m.f_dof[j] >= 0:
                work[m.f_dof[j]] += U[k, j]
            else:
                ground += U[k, j]
        for e in range(E):
            a, b = m.el_a[e], m.el_b[e]
            offset = 0 if m.el_law[e] == CUBIC_SPRING else n
            D[k, e] = relative(Y[k], a, b, offset)
            square = 0.0
            for i in range(k + 1):
                square += D[i, e] * D[k - i, e]
            D2[k, e] = square
            if m.el_law[e] == CUBIC_SPRING:
                cube = 0.0
                for i in range(k + 1):
                    cube += D2[i, e] * D[k - i, e]
                g = m.el_coef[e] * cube
            elif k < 2:  # c |d'| d' and its first derivative need no sign
                g = m.el_coef[e] * abs(D[0, e]) * (D[0, e] if k == 0 else 2 * D[1, e])
            else:
                if sign[e] == 0.0:
                    sign[e] = direction(D, e, k, scale_v, h_last)
                g = m.el_coef[e] * sign[e] * square
            if a >= 0:
                work[a] -= g
            if b >= 0:
                work[b] += g
        inverse = 1.0 / (k + 1)
        row, below = Y[k + 1], Y[k]
        lowest, highest = (0, n) if everywhere else terms_span(first, last, k + 1, width, orders, n)
        speed, x_row = below[n + lowest:n + highest], row[lowest:highest]
        for i in range(highest - lowest):
            x_row[i] = speed[i] * inverse
        if band.shape[1] == 3:
            tridiagonal_rows(m, band, spans, minv_diagonal, below, work, ground, inverse, row, lowest, highest)
            continue
        if band.shape[1] > 0:
            banded_rows(m, band, spans, minv_diagonal, below, work, ground, inverse, row, lowest, highest)
            continue
        for i in range(n):
            s = -ground
            for q in range(m.mi_ptr[i], m.mi_ptr[i + 1]):
                s += m.mi_val[q] * work[m.mi_idx[q]]
            for q in range(m.a_ptr[i], m.a_ptr[i + 1]):
                s += m.a_val[q] * below[m.a_idx[q]]
            row[n + i] = s * inverse
        for i in range(n):
            work[i] = 0.0


@no_alloc
def state_at(Y, h, y, lowest, highest):
    """y = the state's series Y summed at h, at DOFs lowest..highest-1 (x and v; the rest of y as it is)."""
    n = len(y) // 2
    p = Y.shape[0] - 1
    if highest - lowest == n:  # x and v together: one pass, as the span's two took longer on small scenes
        summed(Y, 0, h, y, p)
        return
    summed(Y, lowest, h, y[lowest:highest], p)
    summed(Y, n + lowest, h, y[n + lowest:n + highest], p)


@inlined
def horner(S, tau, i):
    """The series S[:, i] summed at tau."""
    value = 0.0
    for k in range(S.shape[0] - 1, -1, -1):
        value = value * tau + S[k, i]
    return value


@inlined
def horner_slope(S, tau, i):
    """The series S[:, i] and its derivative, summed at tau."""
    value, slope = 0.0, 0.0
    for k in range(S.shape[0] - 1, -1, -1):
        slope = slope * tau + value
        value = value * tau + S[k, i]
    return value, slope


@no_alloc
def step_size(sizes, p, tol_x, tol_v):
    """The step at which the series' last two terms (sizes from order_sizes), relative to the tolerances (of x and of
    v), fall to SAFETY times 1 (inf if they vanish)."""
    h = math.inf
    for k in (p - 1, p):
        size = max(sizes[0, k] / tol_x, sizes[1, k] / tol_v)
        if size > 0.0:
            h = min(h, size ** (-1.0 / k))
    return SAFETY * h


@no_alloc
def reversal(m, D, sign, h):
    """Where in (0, h] a quadratic damper's velocity first changes sign (its series' root), or h. A velocity larger
    than the sum of its series' other terms' sizes cannot reverse within the step; else the first of SAMPLES points
    past the root brackets it, and Newton's steps, kept inside the bracket, close in on it."""
    first = h
    for e in range(len(m.el_law)):
        if m.el_law[e] == CUBIC_SPRING or sign[e] == 0.0:
            continue
        reach, power = 0.0, 1.0
        for k in range(1, D.shape[0]):
            power *= first
            reach += abs(D[k, e]) * power
        if reach < abs(D[0, e]):
            continue
        lo = 0.0
        for s in range(1, SAMPLES + 1):
            tau = first * s / SAMPLES
            if horner(D, tau, e) * sign[e] >= 0.0:
                lo = tau
                continue
            hi = tau
            guess = 0.5 * (lo + hi)
            for _ in range(50):
                value, slope = horner_slope(D, guess, e)
                if value * sign[e] < 0.0:
                    hi = guess
                else:
                    lo = guess
                step = guess - value / slope if slope != 0.0 else 0.5 * (lo + hi)
                if not lo <= step <= hi:
                    step = 0.5 * (lo + hi)
                if abs(step - guess) <= 4e-16 * hi:
                    break
                guess = step
            first = guess
            break
    return first


@kernel
def aligned_empty(size):
    """An uninitialized array of size doubles that starts on a 64-byte boundary, for the series and the output rows:
    the allocators align to less, and a vector access that spans two cache lines costs two (a run of 100 DOFs writing
    1,001 rows: 0.94 ms aligned, 1.19 ms not, measured in one process)."""
    buffer = np.empty(size + 8)
    skip = (-buffer.ctypes.data % 64) // 8
    return buffer[skip:skip + size]


class Run(NamedTuple):
    """A Taylor run's state between calls of integrate, which stops before a step that would write rows the caller has
    not made ready and goes on from here: the state y = [x, v] (y0 at the start), the series (zero where the motion
    has not reached), the stiffness watch's ring, place (the stretch between cuts, the DOFs moving..moved-1, the
    first row not yet due (0 before the start), the first row waiting for the next step's series) and at (t, the
    peaks of |x|, |v| and |a|, the last step); and what a run works out of the model once (the linear rows as
    diagonals, the stiffness watch's norms: 42 us a call on the 1,000-mass chain)."""

    y: np.ndarray
    Y: np.ndarray
    A: np.ndarray
    ring: np.ndarray
    place: np.ndarray
    at: np.ndarray
    band: np.ndarray
    spans: np.ndarray
    minv_diagonal: np.ndarray
    norms: tuple


SEGMENT, MOVING, MOVED, ROW, PENDING = range(5)
T, PEAK_X, PEAK_V, PEAK_A, H_LAST = range(5)
NEED_ROWS = 6  # after erk's statuses: integrate stopped before rows past rows_ready


def start_run(m, y0, p):
    """A Run of the model's arrays m at the start, from y0 = [x, v], for series of order p."""
    n = len(y0) // 2
    Y = aligned_empty((p + 1) * 2 * n).reshape((p + 1, 2 * n))  # contiguous, so that its loops vectorize
    A = aligned_empty(p * n).reshape((p, n))  # the acceleration's series, the velocity's derivative
    Y[:, :], A[:, :] = 0.0, 0.0
    return Run(np.array(y0, dtype=float), Y, A, np.zeros(WATCH_WINDOW, dtype=np.bool_), np.zeros(5, dtype=np.int64),
               np.zeros(5), *diagonals(m), linear_norms(m))


@kernel
def integrate(m, grid, cuts, rtol, atol, max_steps, bound, boundary, out, zeroed, rows_ready, run, counts, floats):
    """Sum the Taylor series (of run.Y's order p) from run.y over the grid into out's blocks x, v and a, (3, N, n)
    (row 0's x and v are the caller's), restarting at each cut; a status (erk's OK, ...), or NEED_ROWS where the next
    step would write rows past rows_ready: the run is kept in `run`, and a call with more rows ready goes on from
    there, that step worked out again. The acceleration's series is the velocity's derivative, whose terms are
    M^-1 (u - f_nl - K x - C v) order by order: equilibrium's, to order p - 1.
    Tolerances scale with the running peaks of |x|, |v| and |a| (the error is stated relative to the peak); an output
    row drops the terms that add up to less than OUTPUT_SHARE of them, and the rows past the middle of a step that ends
    where the motion stays analytic (not at a cut or a damper's reversal) are summed from the next step's series,
    nearer: the 100-mass chain's rows need 12 to 13 orders on average instead of 17. A step works the series out only
    at the DOFs the motion has reached (active_dofs) and those its terms reach from them (terms_span), and a row is
    summed there only; zeros elsewhere, written here unless the caller has `zeroed` out (a large out is zeroed faster
    in one pass than row by row). boundary > 0 watches for stiffness as erk.integrate does, h |lambda| against the
    series' stability limit. floats (FLOATS of them) receive erk's and, where the run ends OK, the extremes of x and v
    over every row (row 0's from y0), so that the caller need not pass over out to find them. A run that fails writes
    NaN to its rows from where it stopped up to rows_ready."""
    if len(floats) < FLOATS:  # its extremes are written past erk's floats
        raise ValueError("taylor.integrate: floats must hold FLOATS numbers")
    n = m.n
    E = len(m.el_law)
    y, Y, A, place, at = run.y, run.Y, run.A, run.place, run.at
    p = Y.shape[0] - 1
    sizes, thresholds, powers = np.zeros((3, p + 1)), np.zeros(3), np.zeros(p + 1)
    U = np.zeros((p + 1, len(m.f_kind)))
    D, D2 = np.zeros((p + 1, max(E, 1))), np.zeros((p + 1, max(E, 1)))
    sign, node, work, stack = np.zeros(max(E, 1)), np.zeros(2 * n), np.zeros(n), np.zeros(1)
    taus, sums = np.zeros(ROWS), np.zeros(ROWS)
    band, spans, minv_diagonal, norms = run.band, run.spans, run.minv_diagonal, run.norms
    width = band.shape[1] // 2 if band.shape[1] > 0 else n  # CSR rows: every DOF may couple to every other
    orders = coupling_orders(band, spans)
    extremes = floats[EXTREMES:FLOATS]  # row 0's: y0, which holds the zeros the rows keep outside the span
    if place[ROW] == 0:  # the start
        place[MOVING], place[MOVED] = loaded_dofs(m, y)  # the DOFs moving..moved-1 hold every x and v not zero
        place[ROW], place[PENDING] = 1, 1  # the first row not yet due; rows pending..row-1 wait for the next series
        for i in range(n):
            at[PEAK_X], at[PEAK_V] = max(at[PEAK_X], abs(y[i])), max(at[PEAK_V], abs(y[n + i]))
        extremes[0], extremes[1], extremes[2], extremes[3] = y[0], y[0], y[n], y[n]
        widen(y[:n], extremes, 0)
        widen(y[n:], extremes, 1)
        floats[T_REACHED] = at[T] = grid[0]
    moving, moved, row, pending = place[MOVING], place[MOVED], place[ROW], place[PENDING]
    peak_x, peak_v, peak_a, h_last = at[PEAK_X], at[PEAK_V], at[PEAK_A], at[H_LAST]
    t = at[T]
    last_ready = min(rows_ready, len(grid))
    for seg in range(place[SEGMENT], len(cuts) - 1):
        ta, tb = cuts[seg], cuts[seg + 1]
        mid = 0.5 * (ta + tb)
        t = max(t, ta)
        while t < tb:
            lowest, highest = terms_span(moving, moved, p, width, orders, n)  # where its terms may not be zero
            # y and Y[0] are zero beyond the span, which only widens
            Y[0, lowest:highest], Y[0, n + lowest:n + highest] = y[lowest:highest], y[n + lowest:n + highest]
            force_series(m, t, ta, mid, p, U, stack)
            coefficients(m, band, spans, minv_diagonal, p, Y, U, D, D2, sign, peak_v, h_last, work, moving, moved,
                         width, orders)
            order_sizes(Y, sizes, p - 2, p, lowest, highest)  # what the step needs (x's and v's last two orders);
            # the rest where a row needs it
            tol_x, tol_v = max(atol + rtol * peak_x, 1e-300), max(atol + rtol * peak_v, 1e-300)
            h_series = step_size(sizes, p, tol_x, tol_v)
            h = min(h_series, tb - t)
            if E > 0:
                h = reversal(m, D, sign, h)
            t_new = tb if h >= tb - t else t + h
            last = rows_through(grid, row, t_new)
            if last > last_ready:  # rows the caller has not made ready: this step again in the next call
                place[SEGMENT], place[ROW], place[PENDING] = seg, row, pending
                place[MOVING], place[MOVED] = moving, moved
                at[T], at[PEAK_X], at[PEAK_V], at[PEAK_A], at[H_LAST] = t, peak_x, peak_v, peak_a, h_last
                return NEED_ROWS
            counts[NFEV] += p
            start = row == 1 and t == grid[0]
            series_a = pending < row or last > row or start  # the acceleration's series only where a row needs it
            if series_a:
                order_sizes(Y, sizes, np.int64(0), p - 3, lowest, highest)
                acceleration_series(Y, A, lowest, highest)
                for i in range(lowest, highest):
                    peak_a = max(peak_a, abs(A[0, i]))
                if start:
                    out[2, 0, :] = A[0]  # equilibrium's acceleration at the start
                thresholds[0], thresholds[1] = OUTPUT_SHARE * tol_x, OUTPUT_SHARE * tol_v
                thresholds[2] = OUTPUT_SHARE * max(atol + rtol * peak_a, 1e-300)
            if pending < row:  # the last step's second half, nearer this step's start
                emit(Y, A, sizes, thresholds, powers, t, grid, pending, row, out, taus, sums, lowest, highest, zeroed,
                     extremes)
                pending = row
            if t_new <= t or h < 10 * abs(np.nextafter(t, np.inf) - t):
                floats[T_REACHED] = t
                out[:, row:last_ready] = np.nan
                return TOO_SMALL_STEP
            counts[ACCEPTED] += 1
            if counts[ACCEPTED] > max_steps:
                out[:, row:last_ready] = np.nan
                return STEP_BUDGET
            h = t_new - t
            # a step that ends where the motion stays analytic leaves its second half's rows to the next series
            analytic = h == h_series and t_new < tb
            split = rows_through(grid, row, t + 0.5 * h) if analytic else last
            if split > row:
                emit(Y, A, sizes, thresholds, powers, t, grid, row, split, out, taus, sums, lowest, highest, zeroed,
                     extremes)
            pending, row = split, last
            h_last = h
            state_at(Y, h, y, lowest, highest)
            for i in range(lowest, highest):
                peak_x, peak_v = max(peak_x, abs(y[i])), max(peak_v, abs(y[n + i]))
            if moved - moving < n:
                moving, moved = active_dofs(y, moving, moved, lowest, highest, NEGLIGIBLE * tol_x, NEGLIGIBLE * tol_v)
            floats[T_REACHED] = t_new
            status = state_status(y[lowest:highest], bound)  # x and v, as one state: zeros elsewhere
            if status != NOT_FINITE:
                beyond = state_status(y[n + lowest:n + highest], bound)
                status = beyond if beyond != OK else status
            if status == OK and boundary > 0 and held_by_stability(m, y, h, t_new, boundary, norms, node, run.ring,
                                                                   counts, floats):
                status = STIFF
            if status != OK:
                if pending < row:
                    emit(Y, A, sizes, thresholds, powers, t, grid, pending, row, out, taus, sums, lowest, highest,
                         zeroed, extremes)
                if status != STIFF:
                    out[:, row:last_ready] = np.nan
                return status
            t = t_new
    return OK
