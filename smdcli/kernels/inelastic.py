"""Elastoplastic and bilinear (kinematic hardening) 1-DOF oscillators under a support acceleration linear between
its samples, solved exactly event to event: the peaks that inelastic spectra are made of.

Per unit mass, u'' + c u' + r(u) = -a(t), c = 2 zeta w, with the restoring force r of an elastic b w^2 u in
parallel with an elastic-perfectly-plastic (1-b) w^2 (u - u_p), |u - u_p| <= u_y (u_y = fy / k). In each mode
the equation is linear, u'' + c u' + kappa u = F - a0 - s tau:

    elastic       kappa = w^2,    F = (1-b) w^2 u_p   (u_p frozen)
    yielding +/-  kappa = b w^2,  F = -/+ (1-b) w^2 u_y  (u_p = u -/+ u_y follows u)

so u is a particular polynomial plus a homogeneous part with a closed-form transition (oscillatory, over-damped,
or for b = 0 the free-particle forms). Yield is where u - u_p reaches +-u_y (also between two sample points:
where an interior extremum of u passes it), unloading where u' returns to zero; each is located by false position
on the closed form. Peaks of u are extremes at u' = 0: exact at unloading events, refined in elastic pieces.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli import interrupts
from smdcli.kernels.compiler import kernel
from smdcli.kernels.oscillator import _cs

PIECES_PER_PERIOD = 8
MAX_EVENTS_PER_STEP = 1000


@kernel
def _transition(kappa, c, tau):
    """(e11, e12, e21, e22): the homogeneous solution of z'' + c z' + kappa z = 0 over tau."""
    if kappa > 0.0:
        w = math.sqrt(kappa)
        C, S = _cs(w, c / (2.0 * w), tau)
        return C + 0.5 * c * S, S, -kappa * S, C - 0.5 * c * S
    if c > 0.0:
        return 1.0, -math.expm1(-c * tau) / c, 0.0, math.exp(-c * tau)
    return 1.0, tau, 0.0, 1.0


@kernel
def _particular(kappa, c, r0, r1):
    """(p0, p1, p2, p3) of a polynomial solution of u'' + c u' + kappa u = r0 + r1 tau."""
    if kappa > 0.0:
        p1 = r1 / kappa
        return (r0 - c * p1) / kappa, p1, 0.0, 0.0
    if c > 0.0:
        p2 = r1 / (2.0 * c)
        return 0.0, (r0 - 2.0 * p2) / c, p2, 0.0
    return 0.0, 0.0, 0.5 * r0, r1 / 6.0


@kernel
def _state(kappa, c, p0, p1, p2, p3, z0, zv0, tau):
    """(u, u') at tau of a segment whose homogeneous state at its start is (z0, zv0)."""
    e11, e12, e21, e22 = _transition(kappa, c, tau)
    u = e11 * z0 + e12 * zv0 + p0 + tau * (p1 + tau * (p2 + tau * p3))
    v = e21 * z0 + e22 * zv0 + p1 + tau * (2.0 * p2 + 3.0 * tau * p3)
    return u, v


@kernel
def _root(kappa, c, p0, p1, p2, p3, z0, zv0, lo, hi, f_lo, f_hi, of_velocity, level):
    """tau in (lo, hi) where u - level (or u', of_velocity) crosses zero, f_lo and f_hi its values at the ends."""
    side = 0
    tau = hi
    for _ in range(200):
        tau = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (lo < tau < hi):
            tau = 0.5 * (lo + hi)
        u, v = _state(kappa, c, p0, p1, p2, p3, z0, zv0, tau)
        f = v if of_velocity else u - level
        if f == 0.0:
            return tau
        if (f > 0.0) == (f_lo > 0.0):
            lo, f_lo = tau, f
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            hi, f_hi = tau, f
            if side == 1:
                f_lo *= 0.5
            side = 1
        if hi - lo <= 1e-15 * (abs(hi) + abs(lo)) + 1e-300:
            break
    return tau


@kernel
def _step(w, zeta, uy, b, dt, a0, slope, hmax, e_elastic, e_yield, s, peaks):
    """Advance state s = [u, u', u_p, mode] over one record interval (input a0 + slope tau), events located and
    the extremes of u kept in peaks = [max u, min u, events]. e_elastic, e_yield: each mode's transition over a
    piece of a whole interval (dt / ceil(dt / hmax)), computed once per oscillator."""
    c = 2.0 * zeta * w
    # _root's flag as a bool, not a literal False or True: one compile of it, not one per literal
    of_velocity, of_displacement = np.bool_(True), np.bool_(False)
    start = 0.0
    segments = 0
    events = True
    while start < dt:
        mode = s[3]
        kappa = w * w if mode == 0.0 else b * w * w
        if mode == 0.0:
            F = (1.0 - b) * w * w * s[2]
        else:
            F = -mode * (1.0 - b) * w * w * uy
        r0 = F - (a0 + slope * start)
        p0, p1, p2, p3 = _particular(kappa, c, r0, -slope)
        z0, zv0 = s[0] - p0, s[1] - p1
        length = dt - start
        pieces = max(1, int(math.ceil(length / hmax)))
        h = length / pieces
        if start == 0.0:
            e11, e12, e21, e22 = e_elastic if mode == 0.0 else e_yield
        else:  # after an event: pieces of another length
            e11, e12, e21, e22 = _transition(kappa, c, h)
        zu, zv = z0, zv0
        ua, va = s[0], s[1]
        event_at = -1.0
        new_mode = mode
        for j in range(pieces):
            ta, tb = j * h, (j + 1) * h
            zu, zv = e11 * zu + e12 * zv, e21 * zu + e22 * zv
            ub = zu + p0 + tb * (p1 + tb * (p2 + tb * p3))
            vb = zv + p1 + tb * (2.0 * p2 + 3.0 * tb * p3)
            if mode == 0.0:
                top, bottom = s[2] + uy, s[2] - uy
                if ub > top or ub < bottom:  # yield inside the piece
                    level = top if ub > top else bottom
                    event_at = _root(kappa, c, p0, p1, p2, p3, z0, zv0, ta, tb, ua - level, ub - level, of_displacement,
                                     level)
                    new_mode = 1.0 if ub > top else -1.0
                elif (va > 0.0 and vb < 0.0) or (va < 0.0 and vb > 0.0):  # an interior extremum of u
                    reach = h * max(abs(va), abs(vb))
                    high = va > 0.0
                    edge = max(ua, ub) + reach if high else min(ua, ub) - reach
                    if (high and (edge > peaks[0] or edge > top)) or (not high and (edge < peaks[1] or edge < bottom)):
                        t_ext = _root(kappa, c, p0, p1, p2, p3, z0, zv0, ta, tb, va, vb, of_velocity, 0.0)
                        u_ext, _ = _state(kappa, c, p0, p1, p2, p3, z0, zv0, t_ext)
                        if high and u_ext > top:  # it passes the yield surface before turning: yield there
                            event_at = _root(kappa, c, p0, p1, p2, p3, z0, zv0, ta, t_ext, ua - top, u_ext - top,
                                             of_displacement, top)
                            new_mode = 1.0
                        elif not high and u_ext < bottom:
                            event_at = _root(kappa, c, p0, p1, p2, p3, z0, zv0, ta, t_ext, ua - bottom,
                                             u_ext - bottom, of_displacement, bottom)
                            new_mode = -1.0
                        else:
                            peaks[0] = max(peaks[0], u_ext)
                            peaks[1] = min(peaks[1], u_ext)
            elif (mode > 0.0 and vb <= 0.0) or (mode < 0.0 and vb >= 0.0):  # unloading: u' back to zero
                event_at = tb if vb == 0.0 else _root(kappa, c, p0, p1, p2, p3, z0, zv0, ta, tb, va, vb, of_velocity,
                                                      0.0)
                new_mode = 0.0
            if event_at >= 0.0 and events:
                break
            event_at = -1.0
            peaks[0] = max(peaks[0], ub)
            peaks[1] = min(peaks[1], ub)
            ua, va = ub, vb
        if event_at < 0.0:
            s[0], s[1] = ua, va
            if mode != 0.0:
                s[2] = ua - mode * uy
            return
        u, v = _state(kappa, c, p0, p1, p2, p3, z0, zv0, event_at)
        peaks[0] = max(peaks[0], u)
        peaks[1] = min(peaks[1], u)
        s[0], s[1] = u, v
        if mode != 0.0:  # unloading: the plastic deformation stays where yielding left it
            s[2] = u - mode * uy
            s[1] = 0.0
        s[3] = new_mode
        peaks[2] += 1.0
        start += event_at
        segments += 1
        if segments > MAX_EVENTS_PER_STEP:  # a degenerate standstill on the surface: finish the step as it is
            events = False


@kernel
def inelastic_peaks(acceleration, dt, omega, zeta, uy, hardening, out):
    """For each oscillator i from rest: out[i] = (max u, min u, final plastic deformation, yield events)."""
    n = acceleration.shape[0]
    s = np.zeros(4)
    peaks = np.zeros(3)
    for i in range(omega.shape[0]):
        w, b = omega[i], hardening[i]
        c = 2.0 * zeta[i] * w
        hmax = 2.0 * math.pi / w / PIECES_PER_PERIOD
        h = dt / max(1, int(math.ceil(dt / hmax)))
        e_elastic = _transition(w * w, c, h)
        e_yield = _transition(b * w * w, c, h)
        s[:] = 0.0
        peaks[:] = 0.0
        for k in range(n - 1):
            slope = (acceleration[k + 1] - acceleration[k]) / dt
            _step(w, zeta[i], uy[i], b, dt, acceleration[k], slope, hmax, e_elastic, e_yield, s, peaks)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = peaks[0], peaks[1], s[2], peaks[2]


def peaks(acceleration: np.ndarray, dt: float, omega, zeta, uy, hardening, threads: int = 0) -> np.ndarray:
    """(O, 4): max u, min u, final plastic deformation and yield events per oscillator (arrays broadcast to O);
    oscillators shared among threads."""
    a = np.ascontiguousarray(acceleration, dtype=float)
    omega, zeta, uy, hardening = (np.ascontiguousarray(x, dtype=float) for x in
                                  np.broadcast_arrays(omega, zeta, uy, hardening))
    out = np.empty((len(omega), 4))
    threads = threads or min(len(omega), interrupts.usable_cores())
    if threads <= 1:
        inelastic_peaks(a, dt, omega, zeta, uy, hardening, out)
        return out
    shares = [np.arange(t, len(omega), threads) for t in range(threads)]

    def run(share):
        part = np.empty((len(share), 4))
        inelastic_peaks(a, dt, omega[share], zeta[share], uy[share], hardening[share], part)
        out[share] = part

    interrupts.in_threads(run, shares)
    return out
