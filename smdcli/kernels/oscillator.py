"""The peaks of linear 1-DOF oscillators under a support acceleration that is linear between its samples, exact:
each oscillator y'' + 2 zeta w y' + w^2 y = -a(t) is advanced by its closed form, and every extremum of the
measured quantity between two sample points is located as the root of the quantity's closed-form derivative, not
sub-sampled.

Within a record interval the input is a + s tau, so y is a particular line (P0 + P1 tau) plus a homogeneous part
z with z(tau) = exp(sigma tau) [C(tau) z0 + S(tau) (zeta w z0 + z0')], sigma = -zeta w, where C, S are cos and
sin/wd (under-damped), cosh and sinh/q (over-damped) or 1 and tau (critical). Each interval is cut into pieces of
at most an eighth of the period, on which the derivative changes sign at most once where it matters; where it
does and the extremum could pass the largest found so far, the root is found by Newton's method on the closed form
(q'' known there too), from the root of the cubic Hermite interpolant's slope, kept inside the bracket.

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


@inlined
def _propagate(kind, w, z, h, e, pieces, t0, y, v, a0, slope, q_max, t_max, q_min, t_min):
    """Advance (y, v) over `pieces` pieces of length h (transition e) of an interval starting at t0 with input
    a0 + slope tau; returns the new (y, v) and the extremes so far (largest q, its time, smallest q, its time),
    every extremum inside the interval counted."""
    e11, e12, e21, e22 = e
    inv_w2 = 1.0 / (w * w)  # hoisted by the compiler out of the caller's loop once inlined
    P1 = -slope * inv_w2
    P0 = (-a0 - 2.0 * z * w * P1) * inv_w2
    zy, zv = y - P0, v - P1
    q0, d0, _ = _quantity(kind, w, z, y, v, a0, slope)
    for j in range(pieces):
        tau0 = j * h
        ny, nv = e11 * zy + e12 * zv, e21 * zy + e22 * zv
        tau1 = tau0 + h
        y, v = ny + P0 + P1 * tau1, nv + P1
        q1, d1, _ = _quantity(kind, w, z, y, v, a0 + slope * tau1, slope)
        if q1 > q_max:
            q_max, t_max = q1, t0 + tau1
        if q1 < q_min:
            q_min, t_min = q1, t0 + tau1
        # an extremum inside the piece exceeds its ends by less than h max |dq/dt| at the ends: refine it only
        # where it could pass the extreme found so far
        reach = h * max(abs(d0), abs(d1))
        if d0 > 0.0 and d1 < 0.0 and max(q0, q1) + reach > q_max:
            q, theta = _extremum(kind, w, z, zy, zv, P0, P1, a0, slope, tau0, h, q0, q1, d0, d1)
            if q > q_max:
                q_max, t_max = q, t0 + tau0 + theta
        elif d0 < 0.0 and d1 > 0.0 and min(q0, q1) - reach < q_min:
            q, theta = _extremum(kind, w, z, zy, zv, P0, P1, a0, slope, tau0, h, q0, q1, d0, d1)
            if q < q_min:
                q_min, t_min = q, t0 + tau0 + theta
        zy, zv, q0, d0 = ny, nv, q1, d1
    return y, v, q_max, t_max, q_min, t_min


@kernel
def oscillator_extremes(acceleration, dt, omega, zeta, kind, tail_periods, out):
    """For each oscillator i from rest: out[i] = (largest q, its time, smallest q, its time) over the record and
    `tail_periods` of its own periods of free motion after the record's end (the residual response)."""
    n = acceleration.shape[0]
    inv_dt = 1.0 / dt
    for i in range(omega.shape[0]):
        w, z = omega[i], zeta[i]
        period = 2.0 * math.pi / w
        pieces = max(1, int(math.ceil(PIECES_PER_PERIOD * dt / period)))
        q_max = t_max = q_min = t_min = 0.0
        y = v = 0.0
        h = dt / pieces
        e = _piece_propagator(w, z, h)
        for k in range(n - 1):
            slope = (acceleration[k + 1] - acceleration[k]) * inv_dt
            y, v, q_max, t_max, q_min, t_min = _propagate(kind, w, z, h, e, pieces, k * dt, y, v, acceleration[k],
                                                          slope, q_max, t_max, q_min, t_min)
        if tail_periods > 0.0:  # free motion: no input, so pieces of an eighth of the period whatever dt
            h = period / PIECES_PER_PERIOD
            y, v, q_max, t_max, q_min, t_min = _propagate(
                kind, w, z, h, _piece_propagator(w, z, h), int(math.ceil(tail_periods * PIECES_PER_PERIOD)),
                (n - 1) * dt, y, v, 0.0, 0.0, q_max, t_max, q_min, t_min)
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
