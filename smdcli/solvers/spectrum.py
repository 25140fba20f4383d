"""Response spectra of a ground acceleration record, exact to rounding between its samples.

A record is taken as linear between samples. A 1-DOF oscillator y'' + 2 zeta w y' + w^2 y = -a(t) under such an
input is integrated exactly by the matrix exponential of its state augmented with the input's value and slope,
so each sample interval is one exact step: all periods and damping ratios advance together, a vector operation
per record sample. Peers step the same equation by Newmark's average acceleration, which is only second-order
accurate for short periods.

The state is scaled (u = w^2 y, u'/w, a, a'/w) so that every entry of the exponentiated matrix is of order w dt:
the exponential stays well conditioned down to periods shorter than the sample interval. The peak of |y| is the
continuous one: between samples the exact solution is evaluated at sub-points (at least POINTS_PER_PERIOD per
oscillator period) and the largest lobes are refined by a parabola through their three highest points.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

POINTS_PER_PERIOD = 64  # sub-points per oscillator period: 3.5e-6 from a 400x finer sampling, measured
STATE_VALUES = 2**23  # sample states held at once (64 MB each of u and u'): oscillators taken in groups
BLOCK_VALUES = 2**21  # sub-point values held at once (16 MB): a long record is measured in blocks of time
LOBE_MARGIN = 0.02  # lobes sampled within 2 % of the largest are refined: one sampled low may hold the peak


@dataclass(frozen=True)
class Spectrum:
    """Sd (m), Sv = w Sd (m/s) and Sa = w^2 Sd (m/s^2) per damping ratio and period: (Z, P) each."""

    period: np.ndarray
    damping: np.ndarray
    Sd: np.ndarray

    @property
    def omega(self) -> np.ndarray:
        """Circular frequency per period, rad/s."""
        return 2 * math.pi / self.period

    @property
    def Sv(self) -> np.ndarray:
        """Pseudo-spectral velocity, m/s."""
        return self.Sd * self.omega

    @property
    def Sa(self) -> np.ndarray:
        """Pseudo-spectral acceleration, m/s^2."""
        return self.Sd * self.omega**2


MAX_SUB_POINTS = 4096  # sub-points per record interval: a period below dt / 64 has no meaning on such a record
MAX_WORK = 4e9  # sub-point values over the whole run (about 10 s on 2 cores)


def spectrum_cost(samples: int, dt: float, periods: np.ndarray, dampings: int) -> tuple[float, float]:
    """(the most sub-points any oscillator needs per record interval, all sub-point values of the run): what
    response_spectrum would compute, estimated in floating point before anything is allocated."""
    with np.errstate(all="ignore"):
        per_interval = np.maximum(1.0, np.ceil(POINTS_PER_PERIOD * dt / np.asarray(periods, dtype=float)))
    most = float(per_interval.max(initial=1.0))
    return most, float(per_interval.sum() * max(samples - 1, 1) * dampings)


def _propagators(omega: np.ndarray, zeta: np.ndarray, dt) -> np.ndarray:
    """exp(A dt) of the scaled augmented state (u, u'/w, a, a'/w), one (4, 4) per oscillator (dt a number or one
    per oscillator): all in one call, as scipy's expm takes a stack."""
    from scipy.linalg import expm

    A = np.zeros((len(omega), 4, 4))
    A[:, 0, 1] = omega
    A[:, 1, 0] = -omega
    A[:, 1, 1] = -2 * zeta * omega
    A[:, 1, 2] = -omega
    A[:, 2, 3] = omega
    return expm(A * np.reshape(dt, (-1, 1, 1)))


def response_spectrum(time: np.ndarray, acceleration: np.ndarray, periods: np.ndarray,
                      dampings: np.ndarray, advance=None) -> Spectrum:
    """Peak relative displacement of every (damping, period) oscillator over the record, from rest; advance(k),
    if given, is told of every k oscillators done."""
    periods = np.asarray(periods, dtype=float)
    dampings = np.asarray(dampings, dtype=float)
    Z, P = len(dampings), len(periods)
    omega = np.tile(2 * math.pi / periods, Z)
    zeta = np.repeat(dampings, P)
    dt = float(time[1] - time[0])
    a = np.asarray(acceleration, dtype=float)
    slope = np.diff(a) / dt  # (N - 1,)
    E = _propagators(omega, zeta, dt)
    N, O = len(a), len(omega)
    sub = np.maximum(1, np.ceil(POINTS_PER_PERIOD * dt * omega / (2 * math.pi))).astype(int)
    peak = np.empty(O)
    group = max(1, STATE_VALUES // N)  # oscillators at a time: memory bounded whatever the record's length
    for lo in range(0, O, group):
        part = slice(lo, min(O, lo + group))
        u, w = _sample_states(E[part], a, slope, omega[part])
        for q in np.unique(sub[part]):
            same = np.flatnonzero(sub[part] == q)
            peak[lo + same] = _continuous_peak(u[:, same], w[:, same], a, slope, omega[part][same],
                                               zeta[part][same], dt, int(q))
        if advance is not None:
            advance(part.stop - part.start)
    return Spectrum(periods, dampings, (peak / omega**2).reshape(Z, P))


def _sample_states(E: np.ndarray, a: np.ndarray, slope: np.ndarray, omega: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """u = w^2 y and u' / w at every record sample, (N, O) each: one exact step per record interval."""
    N, O = len(a), len(omega)
    u = np.zeros((N, O))
    w = np.zeros((N, O))
    for k in range(N - 1):
        s = slope[k] / omega
        u[k + 1] = E[:, 0, 0] * u[k] + E[:, 0, 1] * w[k] + E[:, 0, 2] * a[k] + E[:, 0, 3] * s
        w[k + 1] = E[:, 1, 0] * u[k] + E[:, 1, 1] * w[k] + E[:, 1, 2] * a[k] + E[:, 1, 3] * s
    return u, w


def _continuous_peak(u: np.ndarray, w: np.ndarray, a: np.ndarray, slope: np.ndarray, omega: np.ndarray,
                     zeta: np.ndarray, dt: float, q: int) -> np.ndarray:
    """max |u(t)| over the record for oscillators sampled q times per record interval, in blocks of time that
    overlap by one interval (so every sample is inside some block, where its neighbours are)."""
    N, O = u.shape
    E = None
    if q > 1:
        fractions = np.repeat(np.arange(1, q) * dt / q, O)  # every sub-point's propagator in one stack
        E = _propagators(np.tile(omega, q - 1), np.tile(zeta, q - 1), fractions)[:, 0, :].reshape(q - 1, O, 4)
    best = np.abs(u[0])
    step = max(1, BLOCK_VALUES // (q * O))  # record intervals per block
    for start in range(0, N - 1, step):
        lo, hi = max(0, start - 1), min(N - 1, start + step)
        dense = np.empty((O, (hi - lo) * q + 1))  # oscillator by time: reductions run along contiguous memory
        dense[:, ::q] = u[lo:hi + 1].T
        if E is not None:
            s = (slope[lo:hi, None] / omega).T
            for j in range(1, q):
                e = E[j - 1][:, :, None]
                dense[:, j::q] = e[:, 0] * u[lo:hi].T + e[:, 1] * w[lo:hi].T + e[:, 2] * a[None, lo:hi] + e[:, 3] * s
        best = np.maximum(best, _refined_peak(np.abs(dense, out=dense)))
    return best


def _refined_peak(size: np.ndarray) -> np.ndarray:
    """The largest of each row of |u| samples, every lobe that could hold it refined by a parabola."""
    # A lobe's samples miss its top by at most 1 - cos(pi / POINTS_PER_PERIOD), 0.12 %: every local maximum
    # within LOBE_MARGIN of the row's largest is refined by the parabola through it and its neighbours.
    best = size.max(axis=1)
    middle = size[:, 1:-1]
    candidate = (middle >= size[:, :-2]) & (middle >= size[:, 2:]) & (middle >= (1 - LOBE_MARGIN) * best[:, None])
    rows, i = np.nonzero(candidate)
    i = i + 1
    y0, y1, y2 = size[rows, i - 1], size[rows, i], size[rows, i + 1]
    curvature = y0 - 2 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(curvature < 0, y1 - (y0 - y2) ** 2 / (8 * curvature), y1)
    np.maximum.at(best, rows, vertex)
    return best
