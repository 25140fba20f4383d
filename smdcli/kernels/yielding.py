"""Exact event-to-event motion of a scene whose only nonlinear elements are elastoplastic cores (elastoplastic and
bilinear springs), under a force that is linear between its breakpoints (a recorded ground acceleration): the
compiled form of the event-driven exact solver for the runs of `smd ida`.

Between events the scene is linear, M x'' + C x' + Kt x = g + f(t), Kt being K with each elastic core's stiffness
and g the cores' constant forces (an elastic core's -kc dp, a yielding one's +-fy), f linear on each interval
between breakpoints. In the eigenvectors of its state matrix, A = V diag(lam) V^-1, each coordinate of
w = V^-1 z moves as

    w(s) = e^(lam s) w(0) + s phi1(lam s) beta0 + s^2 phi2(lam s) beta1,

beta0 + beta1 s = V^-1 [0; M^-1 (g + f)], phi1(x) = (e^x - 1) / x, phi2(x) = (e^x - 1 - x) / x^2: exact
(modal_flow.py), and w is carried from step to step (z = Re V w where it is read). A core's guards are rows of z: yield where its
elastic force reaches +-fy (d - dp = +-fy / kc), unload where a yielding core's deformation rate turns. They are
looked at on steps of at most an eighth of the fastest mode's period (pi/4 over the largest |lam|), a crossing
bracketed by a change of sign and a touch by the change of sign of the guard's slope, and located by bisection
to rounding of the time. A yield where the core is not loading outward is no yield; a core that has just unloaded
(or touched its surface) is watched for its next yield once it has left the surface; within the step where it
leaves, for a return past its surface after an excursion below it deeper than rounding.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels.compiler import inlined, kernel
from smdcli.kernels.modal_flow import acceleration_peaks, advance, dot_real, phis, rate_dot, real_into

OK, TOO_MANY_EVENTS, ILL_CONDITIONED, NOT_FINITE, CHATTER = 0, 1, 2, 3, 4
YIELD, UNLOAD = 0, 1
MAX_AT_ONE_TIME = 200
RETURN_SAMPLES = 32  # of a step, where a guard left at its surface may have gone below it and come back
CONDITION_LIMIT = 1e8  # eigenvectors worse than this (a nearly defective mode): the general solver's matrix exponential
EPS = 2.220446049250313e-16


@kernel
def _stiffness(K, R, kc, mode, n):
    """Kt: K with each elastic core's stiffness."""
    Kt = K.copy()
    for e in range(len(kc)):
        if mode[e] == 0:
            for i in range(n):
                for j in range(n):
                    Kt[i, j] += kc[e] * R[e, i] * R[e, j]
    return Kt


@kernel
def _pattern(Minv, K, C, R, kc, mode, n):
    """(A, Kt) of the cores' elastic pattern."""
    Kt = _stiffness(K, R, kc, mode, n)
    A = np.zeros((2 * n, 2 * n))
    for i in range(n):
        A[i, n + i] = 1.0
    A[n:, :n] = -Minv @ Kt
    A[n:, n:] = -Minv @ C
    return A, Kt


@kernel
def _constant(R, kc, fyc, mode, dp, n):
    """g: the cores' constant forces on the masses."""
    g = np.zeros(n)
    for e in range(len(kc)):
        c = -kc[e] * dp[e] if mode[e] == 0 else mode[e] * fyc[e]
        for i in range(n):
            g[i] -= c * R[e, i]
    return g


@inlined
def _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, w, beta0, beta1, s):
    """(G, G') of one of element e's guards at w = w(s), signed so that its event is G rising through 0: an elastic
    core's yield on `side` (G = side (d - dp) - fy / kc), a yielding core's unloading (G = -side d')."""
    if mode[e] == 0:
        return side * (dot_real(cD[e], w) - dp[e]) - fyc[e] / kc[e], side * dot_real(cR[e], w)
    return -side * dot_real(cR[e], w), -side * rate_dot(cR[e], lam, w, beta0, beta1, s)


@inlined
def _rounding(e, mode, dp, kc, fyc, cD, cR, w):
    """How close to its level a guard's value is rounding: 64 ulps of the terms it sums."""
    total = 0.0
    row = cD[e] if mode[e] == 0 else cR[e]
    for i in range(len(w)):
        total += abs(row[i] * w[i])
    if mode[e] == 0:
        total += abs(dp[e]) + fyc[e] / kc[e]
    return 64 * EPS * total


@inlined
def _may_reach(e, side, mode, dp, kc, fyc, cD, cR, lam, w, beta0, beta1, h, G0, S0, level, probe):
    """Whether a hump of the guard in the step could reach its level: its top lies in the half where the slope
    turns (the slope at the middle says which), and rises above that half's start by at most its slope there
    times the half (twice that is the bound: room for the slope's own curvature over an eighth of a period)."""
    advance(lam, w, beta0, beta1, 0.5 * h, probe)
    Gm, Sm = _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, probe, beta0, beta1, 0.5 * h)
    if Gm >= level:
        return True
    if Sm > 0.0:
        return Gm + h * Sm >= level
    return G0 + h * S0 >= level


@inlined
def _rise(e, side, mode, dp, kc, fyc, cD, cR, lam, w, beta0, beta1, lo, hi, level, probe):
    """Where in [lo, hi] the guard, below its level at lo and at or past it at hi, reaches it: by bisection, to
    rounding of the time (the end of the bracket at or past it)."""
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        advance(lam, w, beta0, beta1, mid, probe)
        if _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, probe, beta0, beta1, mid)[0] >= level:
            hi = mid
        else:
            lo = mid
    return hi


@inlined
def _crossing(e, side, mode, dp, kc, fyc, cD, cR, lam, w, w1, beta0, beta1, h, probe):
    """Where in (0, h] the guard first rises past its level (to rounding of the time), or -1: bracketed by its sign
    at the step's ends, or at the top of its hump where its slope turns from rising to falling. The level is raised
    by the guard's rounding: a hump that reaches it only to rounding (an undamped core swinging back to the very
    surface it left) is a touch, not a crossing."""
    level = _rounding(e, mode, dp, kc, fyc, cD, cR, w)
    G0, S0 = _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, w, beta0, beta1, 0.0)
    G1, S1 = _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, w1, beta0, beta1, h)
    hi = -1.0
    if G0 < level <= G1:
        hi = h
    elif G0 < level and G1 < level and S0 > 0.0 and S1 < 0.0 and \
            _may_reach(e, side, mode, dp, kc, fyc, cD, cR, lam, w, beta0, beta1, h, G0, S0, level, probe):
        lo, top = 0.0, h
        for _ in range(200):
            mid = 0.5 * (lo + top)
            if mid <= lo or mid >= top:
                break
            advance(lam, w, beta0, beta1, mid, probe)
            if _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, probe, beta0, beta1, mid)[1] > 0.0:
                lo = mid
            else:
                top = mid
        advance(lam, w, beta0, beta1, top, probe)
        if _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, probe, beta0, beta1, top)[0] >= level:
            hi = top
    if hi < 0.0:
        return -1.0
    return _rise(e, side, mode, dp, kc, fyc, cD, cR, lam, w, beta0, beta1, 0.0, hi, level, probe)


@inlined
def _return(e, side, mode, dp, kc, fyc, cD, cR, lam, w, w1, beta0, beta1, h, probe):
    """Where a yield guard the core left at its surface (an unloading, a touch: not armed) comes back past its level
    in (0, h], or -1: only where the step ends past it after an excursion below it deeper than rounding, its bottom
    the lowest of RETURN_SAMPLES samples refined where the slope turns, the return bracketed from there. Armed again
    only at a step's end, a core that unloaded and yielded again within one step went on elastic past its yield
    force (a bilinear storey 16 ms apart: 1.5e-2 of the peak off, its second yield missing)."""
    level = _rounding(e, mode, dp, kc, fyc, cD, cR, w)
    if _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, w1, beta0, beta1, h)[0] < level:
        return -1.0
    lowest, at = 0.0, -1
    for j in range(1, RETURN_SAMPLES):
        advance(lam, w, beta0, beta1, h * j / RETURN_SAMPLES, probe)
        value = _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, probe, beta0, beta1, h * j / RETURN_SAMPLES)[0]
        if value < lowest:
            lowest, at = value, j
    if at < 0:
        return -1.0
    lo, top = h * (at - 1) / RETURN_SAMPLES, h * (at + 1) / RETURN_SAMPLES  # the bottom, where the slope turns
    for _ in range(200):
        mid = 0.5 * (lo + top)
        if mid <= lo or mid >= top:
            break
        advance(lam, w, beta0, beta1, mid, probe)
        if _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, probe, beta0, beta1, mid)[1] < 0.0:
            lo = mid
        else:
            top = mid
    advance(lam, w, beta0, beta1, top, probe)
    bottom = _guard(e, side, mode, dp, kc, fyc, cD, cR, lam, probe, beta0, beta1, top)[0]
    if min(bottom, lowest) >= -level:
        return -1.0  # at its surface to rounding throughout: no excursion, no return
    lo = top if bottom < lowest else h * at / RETURN_SAMPLES
    return _rise(e, side, mode, dp, kc, fyc, cD, cR, lam, w, beta0, beta1, lo, h, level, probe)


@kernel
def run(Minv, K, C, R, kc, fyc, klin, bt, F0, F1, x0, v0, mode0, dp0, grid, max_events,
        X, Vout, Aout, T, DP, ev_t, ev_e, ev_kind, ev_x, ev_v, ev_T, G0, G1, peak, peak_t):
    """Advance from (x0, v0) with the cores in mode0 (0 elastic, +1, -1 yielding) and plastic deformations dp0 over
    the grid; the force f(t) = F0[i] + F1[i] (t - bt[i]) on [bt[i], bt[i + 1]) (bt ends with inf), the ground's
    acceleration on each DOF G0[i] + G1[i] (t - bt[i]). Fills the outputs (x, v, a relative; the elements' whole
    tensions and plastic deformations), the events, and where peak has n entries each DOF's largest |absolute
    acceleration| located on the solution and when; returns (status, events, the time reached)."""
    n = len(x0)
    E = len(kc)
    N = len(grid)
    m = 2 * n
    mode = mode0.copy()
    dp = dp0.copy()
    armed = np.ones((E, 2), dtype=np.bool_)  # an elastic core's yield guards, [side +, side -]
    t = grid[0]
    seg = 0
    while bt[seg + 1] <= t:
        seg += 1
    z = np.zeros(m)
    z[:n] = x0
    z[n:] = v0
    lam = np.zeros(m, dtype=np.complex128)
    V = np.zeros((m, m), dtype=np.complex128)
    Vinv = np.zeros((m, m), dtype=np.complex128)
    P = np.zeros((m, n), dtype=np.complex128)
    cD = np.zeros((E, m), dtype=np.complex128)
    cR = np.zeros((E, m), dtype=np.complex128)
    Kt = K.copy()
    g = np.zeros(n)
    w = np.zeros(m, dtype=np.complex128)
    w1 = np.zeros(m, dtype=np.complex128)
    probe = np.zeros(m, dtype=np.complex128)
    zk = np.zeros(m)
    beta0 = np.zeros(m, dtype=np.complex128)
    beta1 = np.zeros(m, dtype=np.complex128)
    e_h = np.zeros(m, dtype=np.complex128)
    p1_h = np.zeros(m, dtype=np.complex128)
    p2_h = np.zeros(m, dtype=np.complex128)
    cached_h = -1.0
    cached_pattern = -1
    pattern_count = 0
    omega = 0.0
    ready = False
    last_pattern = np.full(E, -1, dtype=np.int64)
    events = 0
    at_one_time = 0
    last_event_time = -np.inf
    k = 0
    while True:
        if not ready:
            same = True
            for e in range(E):
                if last_pattern[e] != (0 if mode[e] == 0 else 1):
                    same = False
            if not same:
                A, Kt = _pattern(Minv, K, C, R, kc, mode, n)
                lam, vectors = np.linalg.eig(A.astype(np.complex128))
                V = np.ascontiguousarray(vectors)
                Vinv = np.ascontiguousarray(np.linalg.inv(V))
                condition = np.abs(V).sum(axis=0).max() * np.abs(Vinv).sum(axis=0).max()
                if not condition < CONDITION_LIMIT:
                    return ILL_CONDITIONED, events, t
                P = np.ascontiguousarray(Vinv[:, n:]) @ Minv.astype(np.complex128)
                for e in range(E):
                    for j in range(m):
                        cD[e, j] = 0.0
                        cR[e, j] = 0.0
                        for i in range(n):
                            cD[e, j] += R[e, i] * V[i, j]
                            cR[e, j] += R[e, i] * V[n + i, j]
                    last_pattern[e] = 0 if mode[e] == 0 else 1
                omega = np.abs(lam).max()
                pattern_count += 1
            g = _constant(R, kc, fyc, mode, dp, n)
            for i in range(m):
                total = 0.0j
                for j in range(m):
                    total += Vinv[i, j] * z[j]
                w[i] = total
            ready = True
        while k < N and grid[k] <= t:  # outputs due now: the start, a breakpoint or an event on a grid point
            _store(k, z, n, Minv, Kt, C, g, F0[seg] + F1[seg] * (t - bt[seg]), R, klin, kc, fyc, mode, dp, X, Vout,
                   Aout, T, DP)
            k += 1
        if k >= N:
            return OK, events, t
        landing = min(bt[seg + 1], grid[N - 1])
        h = landing - t
        if omega * h > math.pi / 4:
            h = (math.pi / 4) / omega
        f_now = F0[seg] + F1[seg] * (t - bt[seg])
        for i in range(m):
            b0 = 0.0j
            b1 = 0.0j
            for j in range(n):
                b0 += P[i, j] * (g[j] + f_now[j])
                b1 += P[i, j] * F1[seg, j]
            beta0[i] = b0
            beta1[i] = b1
        # a record's steps are one length but for the rounding of the times they run between (within which the
        # step's length is not known anyway): the coefficients of that length are reused
        if abs(h - cached_h) > 4 * EPS * (abs(t) + h) or cached_pattern != pattern_count:
            for i in range(m):
                e_h[i], p1_h[i], p2_h[i] = phis(lam[i] * h)
            cached_h, cached_pattern = h, pattern_count
        for i in range(m):
            w1[i] = e_h[i] * w[i] + h * p1_h[i] * beta0[i] + h * h * p2_h[i] * beta1[i]
        first = h + 1.0
        which, which_side = -1, 0
        for e in range(E):
            for side in (1, -1):
                if mode[e] != 0 and side != mode[e]:
                    continue
                if mode[e] == 0 and not armed[e, 0 if side == 1 else 1]:
                    at = _return(e, side, mode, dp, kc, fyc, cD, cR, lam, w, w1, beta0, beta1, h, probe)
                else:
                    at = _crossing(e, side, mode, dp, kc, fyc, cD, cR, lam, w, w1, beta0, beta1, h, probe)
                if 0.0 <= at < first:
                    first, which, which_side = at, e, side
        step = h if which < 0 else first
        while k < N and grid[k] < t + step:  # outputs inside the step, before its event
            s = grid[k] - t
            advance(lam, w, beta0, beta1, s, probe)
            real_into(V, probe, zk)
            _store(k, zk, n, Minv, Kt, C, g, f_now + F1[seg] * s, R, klin, kc, fyc, mode, dp, X, Vout, Aout, T, DP)
            k += 1
        if which >= 0:
            advance(lam, w, beta0, beta1, step, w1)
        if len(peak) == n:
            acceleration_peaks(n, V, lam, w, w1, beta0, beta1, step, t, G0[seg], G1[seg], t - bt[seg], peak, peak_t,
                                probe)
        for i in range(m):
            w[i] = w1[i]
        real_into(V, w, z)
        for i in range(m):
            if not math.isfinite(z[i]):
                return NOT_FINITE, events, t
        t = landing if which < 0 and h == landing - t else t + step  # a breakpoint landed on exactly
        while bt[seg + 1] <= t:  # the next interval's force (w goes on: the state and the mode are the same)
            seg += 1
        for e in range(E):  # a core that has left its surface is watched for its next yield there
            if mode[e] == 0 and not (armed[e, 0] and armed[e, 1]):
                d = 0.0
                for i in range(n):
                    d += R[e, i] * z[i]
                tolerance = 64 * EPS * (abs(d) + abs(dp[e]) + fyc[e] / kc[e])
                if d - dp[e] < fyc[e] / kc[e] - tolerance:
                    armed[e, 0] = True
                if d - dp[e] > -fyc[e] / kc[e] + tolerance:
                    armed[e, 1] = True
        if which < 0:
            continue
        if t == last_event_time:
            at_one_time += 1
            if at_one_time > MAX_AT_ONE_TIME:
                return CHATTER, events, t
        else:
            at_one_time = 0
        last_event_time = t
        e, side = which, which_side
        while e >= 0:  # the event, and any it sets off at the same instant
            d = 0.0
            rate = 0.0
            speed = 0.0
            for i in range(n):
                d += R[e, i] * z[i]
                rate += R[e, i] * z[n + i]
                speed += abs(R[e, i] * z[n + i])
            if mode[e] == 0:
                armed[e, 0 if side == 1 else 1] = False  # on its surface: watched again once it has left it
                if side * rate <= 64 * EPS * speed:
                    break  # a touch, not loading outward: no yield
                mode[e] = side
                kind = YIELD
            else:
                dp[e] = d - side * fyc[e] / kc[e]
                mode[e] = 0
                armed[e, 0 if side == 1 else 1] = False
                kind = UNLOAD
            if events >= max_events:
                return TOO_MANY_EVENTS, events, t
            ev_t[events] = t
            ev_e[events] = e
            ev_kind[events] = kind
            ev_x[events] = z[:n]
            ev_v[events] = z[n:]
            for j in range(E):
                dj = 0.0
                for i in range(n):
                    dj += R[j, i] * z[i]
                ev_T[events, j] = klin[j] * dj + (kc[j] * (dj - dp[j]) if mode[j] == 0 else mode[j] * fyc[j])
            events += 1
            # a yielding core at zero rate whose acceleration now points back unloads at once
            Kt_now = _stiffness(K, R, kc, mode, n)
            g_now = _constant(R, kc, fyc, mode, dp, n)
            acc = Minv @ (g_now + F0[seg] + F1[seg] * (t - bt[seg]) - Kt_now @ z[:n] - C @ z[n:])
            speed = 64 * EPS * np.abs(z[n:]).max()
            following = -1
            for j in range(E):
                if mode[j] == 0 or j == e:
                    continue
                rj = 0.0
                aj = 0.0
                for i in range(n):
                    rj += R[j, i] * z[n + i]
                    aj += R[j, i] * acc[i]
                if mode[j] * rj <= speed and mode[j] * aj < 0.0:
                    following = j
                    break
            if following >= 0:
                side = mode[following]
            e = following
        ready = False


@inlined
def _store(k, z, n, Minv, Kt, C, g, f, R, klin, kc, fyc, mode, dp, X, Vout, Aout, T, DP):
    """Output point k: x, v, the relative acceleration, each element's whole tension and plastic deformation."""
    for i in range(n):
        X[k, i] = z[i]
        Vout[k, i] = z[n + i]
    for i in range(n):
        total = 0.0
        for j in range(n):
            force = g[j] + f[j]
            for q in range(n):
                force -= Kt[j, q] * z[q] + C[j, q] * z[n + q]
            total += Minv[i, j] * force
        Aout[k, i] = total
    for e in range(len(kc)):
        d = 0.0
        for i in range(n):
            d += R[e, i] * z[i]
        if mode[e] == 0:
            T[k, e] = klin[e] * d + kc[e] * (d - dp[e])
            DP[k, e] = dp[e]
        else:
            T[k, e] = klin[e] * d + mode[e] * fyc[e]
            DP[k, e] = d - mode[e] * fyc[e] / kc[e]
