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
the bracket.

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


BLOCK = 256  # piece ends held for the second pass: 8 KB, in the first-level cache


@inlined
def _candidates(h, qs, ds, q_max, q_min, i):
    """Whether the piece from end i - 1 to end i (q and dq/dt in qs, ds) may hold an extremum past q_max or q_min:
    dq/dt changes sign there, and the extremum exceeds the piece's ends by less than h max |dq/dt| at the ends.
    Bitwise operators, not `and`: no branch, so a loop over the pieces vectorizes."""
    q0, q1, d0, d1 = qs[i - 1], qs[i], ds[i - 1], ds[i]
    reach = h * max(abs(d0), abs(d1))
    return (((d0 > 0.0) & (d1 < 0.0) & (max(q0, q1) + reach > q_max))
            | ((d0 < 0.0) & (d1 > 0.0) & (min(q0, q1) - reach < q_min)))


@inlined
def _particular(acceleration, inv_dt, inv_w2, zw, k):
    """Interval k's input (value a0 at its start, slope) and the line P0 + P1 tau that answers it."""
    a0 = acceleration[k]
    slope = (acceleration[k + 1] - a0) * inv_dt
    P1 = -slope * inv_w2
    return a0, slope, (-a0 - 2.0 * zw * P1) * inv_w2, P1


@inlined
def _sweep(kind, w, z, acceleration, dt, pieces, h, e, t_start, y, v, q_max, t_max, q_min, t_min, ys, vs, qs, ds):
    """Advance (y, v) from t_start over the intervals of `acceleration` (samples dt apart, the input a line between
    them), each cut into `pieces` pieces of length h with transition e; returns the new (y, v) and the extremes so
    far (largest q, its time, smallest q, its time), every extremum inside an interval counted. ys, vs, qs and ds
    are scratch for a block's piece ends.

    Blocks of BLOCK piece ends, in two passes: the first steps the closed form, keeping each piece end's state, q
    and dq/dt; the second refines the pieces whose extremum could pass the extremes found by the block's end. The
    stepping loop is then free of the tests on dq/dt's sign, which mispredict at every turn of the oscillator, and
    the tests run in a loop that vectorizes (one thread, 200 periods of a 4,001-sample record: 5.8 ms, was 6.6)."""
    e11, e12, e21, e22 = e
    inv_w2, zw, inv_dt = 1.0 / (w * w), z * w, 1.0 / dt
    intervals = acceleration.shape[0] - 1
    per_block = max(1, BLOCK // pieces)
    for first in range(0, intervals, per_block):
        a0, slope, _, _ = _particular(acceleration, inv_dt, inv_w2, zw, first)
        q, d, _ = _quantity(kind, w, z, y, v, a0, slope)
        ys[0], vs[0], qs[0], ds[0] = y, v, q, d
        count = 0
        for k in range(first, min(intervals, first + per_block)):
            a0, slope, P0, P1 = _particular(acceleration, inv_dt, inv_w2, zw, k)
            zy, zv = y - P0, v - P1  # the homogeneous part
            for j in range(1, pieces + 1):
                zy, zv = e11 * zy + e12 * zv, e21 * zy + e22 * zv
                tau = j * h
                y, v = zy + P0 + P1 * tau, zv + P1
                q, d, _ = _quantity(kind, w, z, y, v, a0 + slope * tau, slope)
                count += 1
                ys[count], vs[count], qs[count], ds[count] = y, v, q, d
                if q > q_max:
                    q_max, t_max = q, t_start + k * dt + tau
                if q < q_min:
                    q_min, t_min = q, t_start + k * dt + tau
        hits = 0
        for i in range(1, count + 1):
            hits += _candidates(h, qs, ds, q_max, q_min, i)
        for i in range(1, count + 1 if hits else 1):
            if not _candidates(h, qs, ds, q_max, q_min, i):
                continue
            k = first + (i - 1) // pieces
            tau0 = ((i - 1) % pieces) * h
            a0, slope, P0, P1 = _particular(acceleration, inv_dt, inv_w2, zw, k)
            zy, zv = ys[i - 1] - P0 - P1 * tau0, vs[i - 1] - P1
            q, theta = _extremum(kind, w, z, zy, zv, P0, P1, a0, slope, tau0, h, qs[i - 1], qs[i], ds[i - 1], ds[i])
            if q > q_max:
                q_max, t_max = q, t_start + k * dt + tau0 + theta
            if q < q_min:
                q_min, t_min = q, t_start + k * dt + tau0 + theta
    return y, v, q_max, t_max, q_min, t_min


@kernel
def oscillator_extremes(acceleration, dt, omega, zeta, kind, tail_periods, out):
    """For each oscillator i from rest: out[i] = (largest q, its time, smallest q, its time) over the record and
    `tail_periods` of its own periods of free motion after the record's end (the residual response)."""
    n = acceleration.shape[0]
    tail_pieces = int(math.ceil(tail_periods * PIECES_PER_PERIOD))
    most_pieces = int(math.ceil(PIECES_PER_PERIOD * dt * omega.max() / (2.0 * math.pi))) if len(omega) else 1
    size = max(BLOCK, most_pieces, tail_pieces) + 1
    ys, vs, qs, ds = np.empty(size), np.empty(size), np.empty(size), np.empty(size)
    at_rest = np.zeros(2)  # the input after the record
    for i in range(omega.shape[0]):
        w, z = omega[i], zeta[i]
        period = 2.0 * math.pi / w
        pieces = max(1, int(math.ceil(PIECES_PER_PERIOD * dt / period)))
        h = dt / pieces
        y, v, q_max, t_max, q_min, t_min = _sweep(kind, w, z, acceleration, dt, pieces, h, _piece_propagator(w, z, h),
                                                  0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, ys, vs, qs, ds)
        if tail_pieces > 0:  # free motion, one interval: pieces of an eighth of the period whatever dt
            h = period / PIECES_PER_PERIOD
            _, _, q_max, t_max, q_min, t_min = _sweep(kind, w, z, at_rest, tail_pieces * h, tail_pieces, h,
                                                      _piece_propagator(w, z, h), (n - 1) * dt, y, v, q_max, t_max,
                                                      q_min, t_min, ys, vs, qs, ds)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = q_max, t_max, q_min, t_min


def extremes(acceleration: np.ndarray, dt: float, omega: np.ndarray, zeta: np.ndarray, kind: int,
             tail_periods: float = 0.0, threads: int = 0) -> np.ndarray:
    """(O, 4) largest q, its time, smallest q, its time per oscillator; oscillators shared among threads."""
    import os

    a = np.ascontiguousarray(acceleration, dtype=float)
    omega = np.ascontiguousarray(omega, dtype=float)
    zeta = np.ascontiguousarray(zeta, dtype=float)
    out = np.empty((len(omega), 4))
    threads = threads or min(len(omega), os.cpu_count() or 1)
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
