"""The peaks of linear 1-DOF oscillators under a support acceleration that is linear between its samples, exact:
each oscillator y'' + 2 zeta w y' + w^2 y = -a(t) is advanced by its closed form, and every extremum of the
measured quantity between two sample points is located as the root of the quantity's closed-form derivative, not
sub-sampled.

Within a record interval the input is a + s tau, so y is a particular line (P0 + P1 tau) plus a homogeneous part
z with z(tau) = exp(sigma tau) [C(tau) z0 + S(tau) (zeta w z0 + z0')], sigma = -zeta w, where C, S are cos and
sin/wd (under-damped), cosh and sinh/q (over-damped) or 1 and tau (critical). Each interval is cut into pieces of
at most an eighth of the period, on which the derivative changes sign at most once where it matters; where it
does and the extremum could pass the extremes found by the end of a block of pieces, the root is found by Newton's
method on the closed form (q'' known there too), from the root of the cubic Hermite interpolant's slope, kept inside
the bracket. Oscillators with as many pieces to an interval are stepped LANES at a time, side by side.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli import interrupts
from smdcli.kernels.compiler import inlined, kernel

DISPLACEMENT, ABSOLUTE_ACCELERATION = 0, 1  # the quantity whose extremes are measured
PIECES_PER_PERIOD = 8


@kernel
def _cs(omega, zeta, tau):
    """(exp(sigma tau) C(tau), exp(sigma tau) S(tau)) of the homogeneous solution."""
    decay = math.exp(-zeta * omega * tau)
    if zeta < 1.0:
        wd = omega * math.sqrt(1.0 - zeta * zeta)
        return decay * math.cos(wd * tau), decay * math.sin(wd * tau) / wd
    if zeta > 1.0:
        q = omega * math.sqrt(zeta * zeta - 1.0)
        return decay * math.cosh(q * tau), decay * math.sinh(q * tau) / q
    return decay, decay * tau


@inlined
def _quantity(kind, omega, zeta, y, v, a, slope):
    """(q, dq/dt, d2q/dt2) of the measured quantity from the relative state and the input's value and slope."""
    accel = -2.0 * zeta * omega * v - omega * omega * y - a  # y''
    if kind == DISPLACEMENT:
        return y, v, accel
    jerk = -2.0 * zeta * omega * accel - omega * omega * v - slope  # y''', the input's second derivative zero
    return (-(2.0 * zeta * omega * v + omega * omega * y), -(2.0 * zeta * omega * accel + omega * omega * v),
            -(2.0 * zeta * omega * jerk + omega * omega * accel))


@kernel
def _at(kind, omega, zeta, zy, zv, P0, P1, a0, slope, tau0, theta):
    """(q, dq/dt, d2q/dt2) at tau0 + theta of an interval whose homogeneous state at tau0 is (zy, zv)."""
    c, s = _cs(omega, zeta, theta)
    hy = c * zy + s * (zeta * omega * zy + zv)
    hv = c * zv - s * (omega * omega * zy + zeta * omega * zv)
    tau = tau0 + theta
    return _quantity(kind, omega, zeta, hy + P0 + P1 * tau, hv + P1, a0 + slope * tau, slope)


@inlined
def _hermite_root(h, q0, q1, d0, d1):
    """Where in (0, h) the derivative of the cubic through (q0, d0) at 0 and (q1, d1) at h crosses zero (d0 and d1
    of opposite signs): a guess within O(h^4) of the extremum's time; false position's where the cubic gives none."""
    secant = (q1 - q0) / h
    b = 2.0 * (3.0 * secant - 2.0 * d0 - d1) / h  # the cubic's slope: d0 + b s + c s^2
    c = 3.0 * (d0 + d1 - 2.0 * secant) / (h * h)
    disc = b * b - 4.0 * c * d0
    if disc >= 0.0 and (b != 0.0 or disc > 0.0):
        r = -2.0 * d0 / (b + math.copysign(math.sqrt(disc), b))  # one root without cancellation
        if 0.0 < r < h:
            return r
        if c != 0.0 and r != 0.0:
            r = d0 / (c * r)  # the other: the product of the roots is d0 / c
            if 0.0 < r < h:
                return r
    return h * d0 / (d0 - d1)


@kernel
def _extremum(kind, omega, zeta, zy, zv, P0, P1, a0, slope, tau0, h, q0, q1, d0, d1):
    """(q, theta) where dq/dt crosses zero inside (0, h), q and dq/dt being q0, d0 at 0 and q1, d1 at h (d0 and d1 of
    opposite signs): Newton's method on the closed form from the cubic Hermite guess, kept inside the bracket (three
    evaluations, where false position took eight). It stops where the next step is under 1e-9 h: q is then off the
    extremum by half q'' times the step squared, under 1e-18 q'' h^2."""
    lo, hi, f_lo = 0.0, h, d0
    theta = _hermite_root(h, q0, q1, d0, d1)
    q = q0
    for _ in range(100):
        q, f, curvature = _at(kind, omega, zeta, zy, zv, P0, P1, a0, slope, tau0, theta)
        if f == 0.0:
            break
        if (f > 0.0) == (f_lo > 0.0):
            lo, f_lo = theta, f
        else:
            hi = theta
        step = -f / curvature if curvature != 0.0 else math.inf
        if abs(step) <= 1e-9 * h or hi - lo <= 1e-13 * h:
            break
        guess = theta + step
        theta = guess if lo < guess < hi else 0.5 * (lo + hi)
    return q, theta


@kernel
def _piece_propagator(w, z, h):
    """The homogeneous solution's transition over one piece of length h: (e11, e12, e21, e22)."""
    c, s = _cs(w, z, h)
    return c + s * z * w, s, -s * w * w, c - s * z * w


BLOCK = 32  # piece ends held for the second pass, LANES oscillators each: 32 KB, in the first-level cache
LANES = 32  # oscillators stepped side by side (8 and 16: 3.7 and 3.1 ms where 32 take 3.0)
# A group's lanes, a column each: rows of osc, what the stepping reads (the oscillator's constants and its
# interval's particular line), and of state, what it writes (the relative motion, the extremes so far and their
# times, the homogeneous part, the extremes before a block, a block's count of candidate pieces). Two arrays: rows
# of one array, which the compiler cannot tell apart, kept the lanes' loops from vectorizing.
W, ZETA, H, E11, E12, E21, E22, INV_W2, ZW, P0, P1 = range(11)
Y, V, Q_MAX, T_MAX, Q_MIN, T_MIN, ZY, ZV, MAX_BEFORE, MIN_BEFORE, HITS = range(11)


@inlined
def _candidate(h, q0, q1, d0, d1, q_max, q_min):
    """Whether a piece from (q0, d0) to (q1, d1) (q and dq/dt at its ends) may hold an extremum past q_max or q_min:
    dq/dt changes sign there, and the extremum exceeds the piece's ends by less than h max |dq/dt| at the ends.
    Bitwise operators, not `and`: no branch, so a loop over the lanes vectorizes."""
    reach = h * max(abs(d0), abs(d1))
    return (((d0 > 0.0) & (d1 < 0.0) & (max(q0, q1) + reach > q_max))
            | ((d0 < 0.0) & (d1 > 0.0) & (min(q0, q1) - reach < q_min)))


@inlined
def _particular(a0, slope, inv_w2, zw):
    """The line P0 + P1 tau that answers an interval's input (value a0 at its start, slope): (P0, P1)."""
    line_slope = -slope * inv_w2
    return (-a0 - 2.0 * zw * line_slope) * inv_w2, line_slope


@inlined
def _input(acceleration, inv_dt, k):
    """Interval k's input: its value at the start and its slope (the sample difference times 1/dt)."""
    a0 = acceleration[k]
    return a0, (acceleration[k + 1] - a0) * inv_dt


@inlined
def _pieces(kind, lanes, osc, state, ends, count, pieces, a0, slope):
    """Step the lanes over an interval's pieces from their homogeneous parts, each piece end's y, v, q and dq/dt into
    ends' rows count + 1.., the extremes' values (not their times) into state; the new count. Only selects in the
    lanes' loop, no branches (times kept there did not vectorize), and kind a constant where it is inlined: the loop
    vectorizes."""
    L = LANES
    for j in range(1, pieces + 1):
        count += 1
        row = ends[count]
        for lane in range(lanes):
            hy, hv = state[ZY, lane], state[ZV, lane]
            hy, hv = osc[E11, lane] * hy + osc[E12, lane] * hv, osc[E21, lane] * hy + osc[E22, lane] * hv
            state[ZY, lane], state[ZV, lane] = hy, hv
            tau = j * osc[H, lane]
            y, v = hy + osc[P0, lane] + osc[P1, lane] * tau, hv + osc[P1, lane]
            q, d, _ = _quantity(kind, osc[W, lane], osc[ZETA, lane], y, v, a0 + slope * tau, slope)
            row[lane], row[L + lane], row[2 * L + lane], row[3 * L + lane] = y, v, q, d
            q_max, q_min = state[Q_MAX, lane], state[Q_MIN, lane]
            state[Q_MAX, lane] = q if q > q_max else q_max
            state[Q_MIN, lane] = q if q < q_min else q_min
    return count


@inlined
def _sweep(kind, lanes, osc, state, acceleration, dt, pieces, t_start, ends):
    """Advance `lanes` oscillators side by side from t_start over the intervals of `acceleration` (samples dt
    apart, the input a line between them), each cut into `pieces` pieces, lane l's osc[H, l] long; every extremum
    inside an interval counted in the extremes. osc and state: the rows named above, updated; ends: scratch for a
    block's piece ends, a row each (y, v, q, dq/dt of the lanes side by side).

    Blocks of BLOCK piece ends, in two passes: the first steps the closed form, keeping each piece end's state, q
    and dq/dt; the second finds the time of a block's new extreme sample, and refines the pieces whose extremum could
    pass the extremes found by the block's end. One oscillator's step waits on the last (its transition's
    multiply-adds); LANES of them side by side fill the vector units, where one at a time left them idle (one thread,
    200 periods of a 4,001-sample record at 5 %: 3.0-3.3 ms, were 5.3-5.4); the tests on dq/dt's sign, which
    mispredict at every turn, run in loops without branches."""
    L = LANES
    inv_dt = 1.0 / dt
    intervals = acceleration.shape[0] - 1
    per_block = max(1, BLOCK // pieces)
    for first in range(0, intervals, per_block):
        a0, slope = _input(acceleration, inv_dt, first)
        row = ends[0]
        for lane in range(lanes):
            y, v = state[Y, lane], state[V, lane]
            q, d, _ = _quantity(kind, osc[W, lane], osc[ZETA, lane], y, v, a0, slope)
            row[lane], row[L + lane], row[2 * L + lane], row[3 * L + lane] = y, v, q, d
            state[MAX_BEFORE, lane], state[MIN_BEFORE, lane] = state[Q_MAX, lane], state[Q_MIN, lane]
        count = 0
        for k in range(first, min(intervals, first + per_block)):
            a0, slope = _input(acceleration, inv_dt, k)
            for lane in range(lanes):
                osc[P0, lane], osc[P1, lane] = _particular(a0, slope, osc[INV_W2, lane], osc[ZW, lane])
                state[ZY, lane] = state[Y, lane] - osc[P0, lane]  # the homogeneous part
                state[ZV, lane] = state[V, lane] - osc[P1, lane]
            if kind == DISPLACEMENT:
                count = _pieces(DISPLACEMENT, lanes, osc, state, ends, count, pieces, a0, slope)
            else:
                count = _pieces(ABSOLUTE_ACCELERATION, lanes, osc, state, ends, count, pieces, a0, slope)
            for lane in range(lanes):
                state[Y, lane], state[V, lane] = ends[count, lane], ends[count, L + lane]
        for lane in range(lanes):
            h = osc[H, lane]
            if state[Q_MAX, lane] > state[MAX_BEFORE, lane] or state[Q_MIN, lane] < state[MIN_BEFORE, lane]:
                for i in range(1, count + 1):  # the first sample at the block's new extreme: its time
                    k, j = first + (i - 1) // pieces, (i - 1) % pieces + 1
                    q = ends[i, 2 * L + lane]
                    if q == state[Q_MAX, lane] and state[Q_MAX, lane] > state[MAX_BEFORE, lane]:
                        state[T_MAX, lane] = t_start + k * dt + j * h
                        state[MAX_BEFORE, lane] = state[Q_MAX, lane]
                    if q == state[Q_MIN, lane] and state[Q_MIN, lane] < state[MIN_BEFORE, lane]:
                        state[T_MIN, lane] = t_start + k * dt + j * h
                        state[MIN_BEFORE, lane] = state[Q_MIN, lane]
            state[HITS, lane] = 0.0
        for i in range(1, count + 1):
            before, at = ends[i - 1], ends[i]
            for lane in range(lanes):
                state[HITS, lane] += _candidate(osc[H, lane], before[2 * L + lane], at[2 * L + lane],
                                                before[3 * L + lane], at[3 * L + lane], state[Q_MAX, lane],
                                                state[Q_MIN, lane])
        for lane in range(lanes):
            if state[HITS, lane] == 0.0:
                continue
            h, inv_w2, zw = osc[H, lane], osc[INV_W2, lane], osc[ZW, lane]
            for i in range(1, count + 1):
                q0, q1 = ends[i - 1, 2 * L + lane], ends[i, 2 * L + lane]
                d0, d1 = ends[i - 1, 3 * L + lane], ends[i, 3 * L + lane]
                if not _candidate(h, q0, q1, d0, d1, state[Q_MAX, lane], state[Q_MIN, lane]):
                    continue
                k = first + (i - 1) // pieces
                tau0 = ((i - 1) % pieces) * h
                a0, slope = _input(acceleration, inv_dt, k)
                p0, p1 = _particular(a0, slope, inv_w2, zw)
                q, theta = _extremum(kind, osc[W, lane], osc[ZETA, lane], ends[i - 1, lane] - p0 - p1 * tau0,
                                     ends[i - 1, L + lane] - p1, p0, p1, a0, slope, tau0, h, q0, q1, d0, d1)
                if q > state[Q_MAX, lane]:
                    state[Q_MAX, lane], state[T_MAX, lane] = q, t_start + k * dt + tau0 + theta
                if q < state[Q_MIN, lane]:
                    state[Q_MIN, lane], state[T_MIN, lane] = q, t_start + k * dt + tau0 + theta


@inlined
def _lanes_at(osc, lanes, omega, zeta, order, first, h_of):
    """Fill osc's lanes with oscillators order[first:first + lanes], lane l's pieces h_of[its index] long."""
    for lane in range(lanes):
        i = order[first + lane]
        w, z = omega[i], zeta[i]
        h = h_of[i]
        e11, e12, e21, e22 = _piece_propagator(w, z, h)
        osc[W, lane], osc[ZETA, lane], osc[H, lane] = w, z, h
        osc[E11, lane], osc[E12, lane], osc[E21, lane], osc[E22, lane] = e11, e12, e21, e22
        osc[INV_W2, lane], osc[ZW, lane] = 1.0 / (w * w), z * w


@kernel
def oscillator_extremes(acceleration, dt, omega, zeta, kind, tail_periods, out):
    """For each oscillator i from rest: out[i] = (largest q, its time, smallest q, its time) over the record and
    `tail_periods` of its own periods of free motion after the record's end (the residual response). Oscillators
    with as many pieces to an interval run LANES at a time."""
    n = acceleration.shape[0]
    count = omega.shape[0]
    tail_pieces = int(math.ceil(tail_periods * PIECES_PER_PERIOD))
    pieces_of = np.empty(count, dtype=np.int64)
    record_h, tail_h = np.empty(count), np.empty(count)
    for i in range(count):
        period = 2.0 * math.pi / omega[i]
        pieces_of[i] = max(1, int(math.ceil(PIECES_PER_PERIOD * dt / period)))
        record_h[i] = dt / pieces_of[i]
        tail_h[i] = period / PIECES_PER_PERIOD  # free motion, one interval: pieces of an eighth of the period
    order = np.argsort(pieces_of, kind="mergesort")
    most_pieces = pieces_of.max() if count else 1
    size = max(BLOCK, most_pieces, tail_pieces) + 1
    osc, state, ends = np.empty((11, LANES)), np.empty((11, LANES)), np.empty((size, 4 * LANES))
    at_rest = np.zeros(2)  # the input after the record
    first = 0
    while first < count:
        pieces = pieces_of[order[first]]
        lanes = 1
        while lanes < LANES and first + lanes < count and pieces_of[order[first + lanes]] == pieces:
            lanes += 1
        state[:, :] = 0.0
        _lanes_at(osc, lanes, omega, zeta, order, first, record_h)
        _sweep(kind, lanes, osc, state, acceleration, dt, pieces, 0.0, ends)
        if tail_pieces > 0:
            _lanes_at(osc, lanes, omega, zeta, order, first, tail_h)
            # one interval at rest (k = 0), so its dt scales nothing: the pieces are each lane's own
            _sweep(kind, lanes, osc, state, at_rest, 1.0, tail_pieces, (n - 1) * dt, ends)
        for lane in range(lanes):
            i = order[first + lane]
            out[i] = state[Q_MAX, lane], state[T_MAX, lane], state[Q_MIN, lane], state[T_MIN, lane]
        first += lanes


def extremes(acceleration: np.ndarray, dt: float, omega: np.ndarray, zeta: np.ndarray, kind: int,
             tail_periods: float = 0.0, threads: int = 0) -> np.ndarray:
    """(O, 4) largest q, its time, smallest q, its time per oscillator; oscillators shared among threads, at most one
    for each LANES of them (a group of fewer lanes takes as long as a full one)."""
    a = np.ascontiguousarray(acceleration, dtype=float)
    omega = np.ascontiguousarray(omega, dtype=float)
    zeta = np.ascontiguousarray(zeta, dtype=float)
    out = np.empty((len(omega), 4))
    threads = threads or min(-(-len(omega) // LANES), interrupts.usable_cores())
    if threads <= 1:
        oscillator_extremes(a, dt, omega, zeta, kind, tail_periods, out)
        return out
    # interleaved shares: short and long periods (many and few pieces) spread evenly over the threads
    shares = [np.arange(t, len(omega), threads) for t in range(threads)]

    def run(share):
        part = np.empty((len(share), 4))
        oscillator_extremes(a, dt, omega[share], zeta[share], kind, tail_periods, part)
        out[share] = part

    interrupts.in_threads(run, shares)
    return out
