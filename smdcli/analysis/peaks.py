"""Peaks located on the solution between its samples, not read off the samples: the largest |x| of each DOF from the
quintic Hermite interpolant of x, v and a on the intervals beside each sample that may hold it. A sample maximum
is short of the true peak by about (omega h)^2 / 8 of it (three_dof_forced's m1 read 0.13852 m for 0.138572); the
quintic's error is about (omega h)^6 / 720 (2e-9 at omega h = 0.1), and where it is not good to
better than the samples (a coarse grid, an interval holding an event's jump) the sample stands. Every candidate
interval at once: the quintic read at SEEDS points, then Newton's steps on its slope from the best (1,000 DOFs in
0.15 s, where a root-finder an interval took 7.6 s).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

CANDIDATES = 8  # sample maxima of each DOF looked at between their samples, the largest first
SEEDS = 17  # points of an interval the quintic is read at before Newton's steps find its turn


def _quintics(x0, v0, a0, x1, v1, a1, h):
    """Coefficients (lowest first, last axis) in s = (t - t0) / h in [0, 1] of the quintics with these values,
    slopes and second derivatives at both ends; every argument an array of intervals."""
    d0, d1, c2 = v0 * h, v1 * h, a0 * h * h / 2
    r0 = x1 - (x0 + d0 + c2)
    r1 = d1 - (d0 + 2 * c2)
    r2 = a1 * h * h - 2 * c2
    return np.stack([x0, d0, c2, 10 * r0 - 4 * r1 + r2 / 2, -15 * r0 + 7 * r1 - r2, 6 * r0 - 3 * r1 + r2 / 2],
                    axis=-1)


def _value(c, s, order=0):
    """The quintics c (intervals, 6) or a derivative of them at s (intervals,)."""
    powers = np.arange(6)
    factor = np.ones(6)
    for k in range(order):
        factor = factor * np.maximum(powers - k, 0)
    exponents = np.maximum(powers - order, 0)
    return np.sum(c * factor * s[:, None] ** exponents, axis=-1)


def _interval_peaks(x0, v0, a0, x1, v1, a1, h) -> np.ndarray:
    """The largest |x| on each interval of the quintic Hermite interpolant, nan where the quintic and the cubic (x, v
    only) disagree by more than what locating the peak could gain (the interpolant not good there)."""
    c = _quintics(x0, v0, a0, x1, v1, a1, h)
    grid = np.linspace(0.0, 1.0, SEEDS)
    values = c @ (grid[:, None] ** np.arange(6)).T  # (intervals, SEEDS)
    s = grid[np.argmax(np.abs(values), axis=1)]
    for _ in range(4):  # Newton on the slope, from the best seed; an end stays an end
        slope, curvature = _value(c, s, 1), _value(c, s, 2)
        step = np.where(curvature != 0, slope / np.where(curvature != 0, curvature, 1.0), 0.0)
        s = np.clip(s - step, 0.0, 1.0)
    best = np.maximum(np.abs(_value(c, s)), np.abs(values).max(axis=1))
    # the cubic Hermite on x and v alone: how far the interpolant is from settled at the peak found
    d0, d1 = v0 * h, v1 * h
    cubic = (x0 * (2 * s ** 3 - 3 * s ** 2 + 1) + d0 * (s ** 3 - 2 * s ** 2 + s) + x1 * (-2 * s ** 3 + 3 * s ** 2)
             + d1 * (s ** 3 - s ** 2))
    gain = best - np.maximum(np.abs(x0), np.abs(x1))
    return np.where(np.abs(np.abs(_value(c, s)) - np.abs(cubic)) > np.maximum(gain, 0.0), np.nan, best)


def located_peaks(time: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray,
                  events: np.ndarray = np.empty(0)) -> np.ndarray:
    """The largest |x| of each DOF (columns) over the run, located between samples; intervals holding an event
    (`events`, the times where the acceleration or the state jumps) keep their samples."""
    finite = np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1) & np.isfinite(a).all(axis=1)
    magnitude = np.where(np.isfinite(x), np.abs(x), 0.0)
    peaks = magnitude.max(axis=0) if len(x) else np.zeros(x.shape[1])
    if len(time) < 2:
        return peaks
    usable = finite[:-1] & finite[1:]
    if len(events):
        usable[np.clip(np.searchsorted(time, events, side="right") - 1, 0, len(time) - 2)] = False
        usable[np.clip(np.searchsorted(time, events, side="left") - 1, 0, len(time) - 2)] = False
    # each DOF's largest sample maxima, and the intervals either side of them
    local = (magnitude >= np.roll(magnitude, 1, axis=0)) & (magnitude >= np.roll(magnitude, -1, axis=0))
    ranked = np.argsort(np.where(local, magnitude, -1.0), axis=0)[::-1][:CANDIDATES]  # (CANDIDATES, n)
    dof = np.broadcast_to(np.arange(x.shape[1]), ranked.shape)
    keep = local[ranked, dof]
    rows, columns = ranked[keep], dof[keep]
    k = np.concatenate([rows - 1, rows])
    j = np.concatenate([columns, columns])
    inside = (k >= 0) & (k < len(time) - 1)
    k, j = k[inside], j[inside]
    k, j = k[usable[k]], j[usable[k]]
    if not len(k):
        return peaks
    found = _interval_peaks(x[k, j], v[k, j], a[k, j], x[k + 1, j], v[k + 1, j], a[k + 1, j], time[k + 1] - time[k])
    found = np.where(np.isnan(found), 0.0, found)
    np.maximum.at(peaks, j, found)
    return peaks
