"""The motion of a linear mode in the eigenvectors of its state matrix, A = V diag(lam) V^-1, under a force linear in
time: each coordinate of w = V^-1 z moves as

    w(s) = e^(lam s) w(0) + s phi1(lam s) beta0 + s^2 phi2(lam s) beta1,

beta0 + beta1 s = V^-1 b(s), phi1(x) = (e^x - 1) / x, phi2(x) = (e^x - 1 - x) / x^2: exact. Rows of z (and of z', z'')
read from w; the absolute accelerations' peaks located on it. Inlined into the yielding frame's kernel (yielding.py).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.kernels.compiler import inlined


@inlined
def phis(x):
    """(e^x, phi1(x), phi2(x)) of a complex x: the series near 0, where the closed forms cancel."""
    if abs(x) < 0.5:
        p1 = 0.0j
        p2 = 0.0j
        term = 1.0 + 0.0j  # x^k / (k + 1)!
        for k in range(20):
            p1 += term
            p2 += term / (k + 2)
            term = term * x / (k + 2)
        return 1.0 + x * p1, p1, p2
    e = np.exp(x)
    return e, (e - 1.0) / x, (e - 1.0 - x) / (x * x)


@inlined
def advance(lam, w0, beta0, beta1, s, out):
    """w(s) into out."""
    for i in range(len(lam)):
        e, p1, p2 = phis(lam[i] * s)
        out[i] = e * w0[i] + s * p1 * beta0[i] + s * s * p2 * beta1[i]


@inlined
def dot_real(c, w):
    """Re(c . w)."""
    total = 0.0
    for i in range(len(c)):
        total += c[i].real * w[i].real - c[i].imag * w[i].imag
    return total


@inlined
def rate_dot(c, lam, w, beta0, beta1, s):
    """Re(c . w'(s)), w' = lam w + beta0 + beta1 s."""
    total = 0.0
    for i in range(len(c)):
        q = lam[i] * w[i] + beta0[i] + beta1[i] * s
        total += c[i].real * q.real - c[i].imag * q.imag
    return total


@inlined
def real_into(V, w, out):
    """Re(V w) into out."""
    for i in range(len(out)):
        total = 0.0
        for j in range(len(w)):
            total += V[i, j].real * w[j].real - V[i, j].imag * w[j].imag
        out[i] = total


@inlined
def absolute_acceleration(i, n, V, lam, w, beta0, beta1, s, a0, a1, since):
    """(absolute acceleration of DOF i, its rate) at w = w(s): the relative one, row n + i of z' = V w' (w' = lam w +
    beta0 + beta1 s, w'' = lam w' + beta1), plus the ground's a0 + a1 (since + s)."""
    value = 0.0
    rate = 0.0
    for j in range(len(w)):
        q = lam[j] * w[j] + beta0[j] + beta1[j] * s
        r = lam[j] * q + beta1[j]
        value += V[n + i, j].real * q.real - V[n + i, j].imag * q.imag
        rate += V[n + i, j].real * r.real - V[n + i, j].imag * r.imag
    return value + a0[i] + a1[i] * (since + s), rate + a1[i]


@inlined
def acceleration_peaks(n, V, lam, w0, w1, beta0, beta1, h, t, a0, a1, since, peak, peak_t, probe):
    """Raise each DOF's peak |absolute acceleration| to the step's largest: at its ends, and at a turn inside
    where the turn could pass the peak (twice the larger end slope times the step bounds its rise), bracketed
    where the rate changes sign and found by bisection."""
    for i in range(n):
        A0, S0 = absolute_acceleration(i, n, V, lam, w0, beta0, beta1, 0.0, a0, a1, since)
        A1, S1 = absolute_acceleration(i, n, V, lam, w1, beta0, beta1, h, a0, a1, since)
        for value, at in ((A0, t), (A1, t + h)):
            if abs(value) > peak[i]:
                peak[i], peak_t[i] = abs(value), at
        if S0 * S1 < 0.0 and max(abs(A0), abs(A1)) + 2.0 * h * max(abs(S0), abs(S1)) > peak[i]:
            lo, hi = 0.0, h
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                if mid <= lo or mid >= hi:
                    break
                advance(lam, w0, beta0, beta1, mid, probe)
                if absolute_acceleration(i, n, V, lam, probe, beta0, beta1, mid, a0, a1, since)[1] * S0 > 0.0:
                    lo = mid
                else:
                    hi = mid
            advance(lam, w0, beta0, beta1, lo, probe)
            value = abs(absolute_acceleration(i, n, V, lam, probe, beta0, beta1, lo, a0, a1, since)[0])
            if value > peak[i]:
                peak[i], peak_t[i] = value, t + lo
