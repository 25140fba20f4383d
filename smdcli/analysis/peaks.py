"""Peaks located on the solution between its samples, not read off the samples: the largest |x| of each DOF from the
quintic Hermite interpolant of x, v and a on the intervals beside each sample that may hold it. A sample maximum
is short of the true peak by about (omega h)^2 / 8 of it (a mass resting against a stop read 0.00399977 m for
0.004); the quintic's error is about (omega h)^6 / 720 (2e-9 at omega h = 0.1), and where it is not good to
better than the samples (a coarse grid, an interval holding an event's jump) the sample stands.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

CANDIDATES = 32  # sample maxima of each DOF looked at between their samples, the largest first


def _quintic(x0, v0, a0, x1, v1, a1, h):
    """Coefficients (lowest first) in s = (t - t0) / h in [0, 1] of the quintic with these values, slopes and
    second derivatives at both ends."""
    d0, d1 = v0 * h, v1 * h
    c0, c1 = a0 * h * h, a1 * h * h
    c = np.empty(6)
    c[0], c[1], c[2] = x0, d0, c0 / 2
    # the rest from the conditions at s = 1
    r0 = x1 - (c[0] + c[1] + c[2])
    r1 = d1 - (c[1] + 2 * c[2])
    r2 = c1 - 2 * c[2]
    c[3] = 10 * r0 - 4 * r1 + r2 / 2
    c[4] = -15 * r0 + 7 * r1 - r2
    c[5] = 6 * r0 - 3 * r1 + r2 / 2
    return c


def _interval_peak(x0, v0, a0, x1, v1, a1, h) -> float:
    """The largest |x| on one interval of the quintic Hermite interpolant, nan where the quintic and the cubic (x, v
    only) disagree by more than what locating the peak could gain (the interpolant not good there)."""
    c = _quintic(x0, v0, a0, x1, v1, a1, h)
    slope = np.polynomial.polynomial.polyder(c)
    roots = np.polynomial.polynomial.polyroots(slope)
    s = np.concatenate([[0.0, 1.0], roots.real[(np.abs(roots.imag) < 1e-12) & (roots.real > 0) & (roots.real < 1)]])
    values = np.polynomial.polynomial.polyval(s, c)
    best = int(np.argmax(np.abs(values)))
    # the cubic Hermite on x and v alone: how far the interpolant is from settled at the peak found
    d0, d1 = v0 * h, v1 * h
    s_best = s[best]
    cubic = (x0 * (2 * s_best ** 3 - 3 * s_best ** 2 + 1) + d0 * (s_best ** 3 - 2 * s_best ** 2 + s_best)
             + x1 * (-2 * s_best ** 3 + 3 * s_best ** 2) + d1 * (s_best ** 3 - s_best ** 2))
    gain = abs(values[best]) - max(abs(x0), abs(x1))
    if abs(values[best] - cubic) > max(gain, 0.0):
        return np.nan
    return float(abs(values[best]))


def located_peaks(time: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray,
                  events: np.ndarray = np.empty(0)) -> np.ndarray:
    """The largest |x| of each DOF (columns) over the run, located between samples; intervals holding an event
    (`events`, times of a nonsmooth run's jumps) keep their samples."""
    finite = np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1) & np.isfinite(a).all(axis=1)
    magnitude = np.where(np.isfinite(x), np.abs(x), 0.0)
    peaks = magnitude.max(axis=0) if len(x) else np.zeros(x.shape[1])
    if len(time) < 2:
        return peaks
    holds_event = np.zeros(len(time) - 1, dtype=bool)
    if len(events):
        where = np.searchsorted(time, events, side="right") - 1
        holds_event[np.clip(where, 0, len(time) - 2)] = True
        holds_event[np.clip(np.searchsorted(time, events, side="left") - 1, 0, len(time) - 2)] = True
    for j in range(x.shape[1]):
        column = magnitude[:, j]
        local = np.flatnonzero((column >= np.roll(column, 1)) & (column >= np.roll(column, -1)))
        for i in local[np.argsort(column[local])[::-1][:CANDIDATES]]:
            for k in (i - 1, i):  # the intervals either side of the sample
                if k < 0 or k >= len(time) - 1 or holds_event[k] or not (finite[k] and finite[k + 1]):
                    continue
                h = float(time[k + 1] - time[k])
                found = _interval_peak(x[k, j], v[k, j], a[k, j], x[k + 1, j], v[k + 1, j], a[k + 1, j], h)
                if found == found:
                    peaks[j] = max(peaks[j], found)
    return peaks
