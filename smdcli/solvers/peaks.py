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

NEAR = 0.05  # sample maxima this close (relative) to a history's largest are looked at between their samples
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


def quintic_coefficients(x0, v0, a0, x1, v1, a1, h) -> np.ndarray:
    """The quintic Hermite interpolant's coefficients (lowest first) in s = (t - t0) / h of one step: the
    polynomial whose values, slopes and second derivatives at both ends are these."""
    return _quintics(np.float64(x0), np.float64(v0), np.float64(a0), np.float64(x1), np.float64(v1), np.float64(a1),
                     np.float64(h))


# (x0, h v0, h^2 a0, x1, h v1, h^2 a1) x powers of s: the quintic Hermite basis, _quintics' of each end's number alone
_HERMITE = np.stack([_quintics(*unit, 1.0) for unit in np.eye(6)])


def _value(c, s, order=0):
    """The quintics c (..., 6) or a derivative of them at s (matching c's leading axes), by Horner's rule."""
    factors = {0: (1, 1, 1, 1, 1, 1), 1: (0, 1, 2, 3, 4, 5), 2: (0, 0, 2, 6, 12, 20)}[order]
    total = c[..., 5] * factors[5]
    for power in range(4, order - 1, -1):
        total = total * s + c[..., power] * factors[power]
    return total


def _interval(time: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k, h, s) of each time: the sample interval holding it, its length and the time's place in it (0 to 1)."""
    k = np.clip(np.searchsorted(time, at, side="right") - 1, 0, max(len(time) - 2, 0))
    h = time[k + 1] - time[k]
    return k, h, np.clip((at - time[k]) / h, 0.0, 1.0)


def quintic_at(time: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray, at: np.ndarray,
               v_left: np.ndarray | None = None, a_left: np.ndarray | None = None) -> np.ndarray:
    """x (N,) read at the times `at` on the quintic Hermite interpolant of its samples x, v, a (exact for a
    displacement whose acceleration is linear between samples, as a record's ground motion); v_left, a_left: the
    left limits at each sample where they differ (an interval's end takes them)."""
    if len(time) < 2:
        return np.full(len(at), float(x[0]) if len(x) else 0.0)
    k, h, s = _interval(time, at)
    v_end, a_end = (v if v_left is None else v_left), (a if a_left is None else a_left)
    return _value(_quintics(x[k], v[k], a[k], x[k + 1], v_end[k + 1], a_end[k + 1], h), s)


def quintic_each(time: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Each column read at its own time: x, v, a (..., N, n) and at (n,) give the (..., n) values of column i at
    at[i] on the quintic Hermite interpolant of its samples (quintic_at's, for many histories at once)."""
    if len(time) < 2:
        return np.asarray(x[..., 0, :], dtype=float)
    k, h, s = _interval(time, at)
    columns, ends = np.arange(len(at)), np.stack([k, k + 1])  # (2, n): each column's interval's ends
    basis = _HERMITE @ (s ** np.arange(6)[:, None])  # (6, n): what each end's x, h v and h^2 a weigh at s
    # the interpolant as a weighed sum of its ends' numbers: half the numpy calls of its coefficients by Horner
    return (x[..., ends, columns] * basis[0::3] + v[..., ends, columns] * (h * basis[1::3])
            + a[..., ends, columns] * (h * h * basis[2::3])).sum(axis=-2)


def _interval_peaks(x0, v0, a0, x1, v1, a1, h) -> tuple[np.ndarray, np.ndarray]:
    """The largest |x| on each interval of the quintic Hermite interpolant, nan where the quintic and the cubic (x, v
    only) disagree by more than what locating the peak could gain (the interpolant not good there), and where in
    the interval it is (0 to 1)."""
    c = _quintics(x0, v0, a0, x1, v1, a1, h)
    grid = np.linspace(0.0, 1.0, SEEDS)
    values = c @ (grid[:, None] ** np.arange(6)).T  # (intervals, SEEDS)
    seed = grid[np.argmax(np.abs(values), axis=1)]
    s = seed
    for _ in range(4):  # Newton on the slope, from the best seed; an end stays an end
        slope, curvature = _value(c, s, 1), _value(c, s, 2)
        step = np.where(curvature != 0, slope / np.where(curvature != 0, curvature, 1.0), 0.0)
        s = np.clip(s - step, 0.0, 1.0)
    best = np.maximum(np.abs(_value(c, s)), np.abs(values).max(axis=1))
    at = np.where(np.abs(_value(c, s)) >= best, s, seed)
    # the cubic Hermite on x and v alone: how far the interpolant is from settled at the peak found
    d0, d1 = v0 * h, v1 * h
    cubic = (x0 * (2 * s ** 3 - 3 * s ** 2 + 1) + d0 * (s ** 3 - 2 * s ** 2 + s) + x1 * (-2 * s ** 3 + 3 * s ** 2)
             + d1 * (s ** 3 - s ** 2))
    gain = best - np.maximum(np.abs(x0), np.abs(x1))
    return np.where(np.abs(np.abs(_value(c, s)) - np.abs(cubic)) > np.maximum(gain, 0.0), np.nan, best), at


def located_peaks(time: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray,
                  events: np.ndarray = np.empty(0), with_times: bool = False):
    """The largest |x| of each DOF (columns of x, v, a (N, n)) over the run, located between samples; intervals
    holding an event (`events`, the times where the acceleration or the state jumps) keep their samples. With
    `with_times`, (peaks, the times they are at)."""
    return row_peaks(time, x.T, v.T, a.T, events, with_times)


def row_peaks(time: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray,
              events: np.ndarray = np.empty(0), with_times: bool = False):
    """located_peaks of histories laid out as rows (histories, N): a sweep's members and DOFs, contiguous in time."""
    # as laid out: v and a are read at the candidate intervals only, and |x| in any order (a run's (N, n) arrays,
    # transposed into rows, would be three copies: 240 MB and a second of a 10,000-DOF run)
    x, v, a = (np.asarray(q, dtype=float) for q in (x, v, a))
    rows, N = x.shape
    magnitude = np.abs(x)
    magnitude[~np.isfinite(magnitude)] = 0.0
    peaks = magnitude.max(axis=1) if N else np.zeros(rows)
    live = np.flatnonzero(peaks > 0)
    if N and len(live) < rows // 2:  # most histories at rest throughout (a wave's far DOFs): locate the others'
        located = row_peaks(time, x[live], v[live], a[live], events, with_times)
        peaks[live], when = (located[0], np.full(rows, time[0])) if with_times else (located, None)
        if with_times:
            when[live] = located[1]
        return (peaks, when) if with_times else peaks
    when = time[magnitude.argmax(axis=1)] if N else np.zeros(rows)
    done = (lambda: (peaks, when)) if with_times else (lambda: peaks)
    if N < 3:
        return done()
    usable = np.ones(N - 1, dtype=bool)
    if len(events):
        usable[np.clip(np.searchsorted(time, events, side="right") - 1, 0, N - 2)] = False
        usable[np.clip(np.searchsorted(time, events, side="left") - 1, 0, N - 2)] = False
    # each history's sample maxima within NEAR of its largest (a located peak gains at most (omega h)^2 / 8 on its
    # samples, 5 % at omega h = 0.6, beyond which the quintic is not trusted), and the intervals either side of them
    inner = magnitude[:, 1:-1]
    candidate = inner >= ((1 - NEAR) * peaks)[:, None]
    candidate &= (inner >= magnitude[:, :-2]) & (inner >= magnitude[:, 2:])
    # a plateau (a history at rest, all zeros where a wave has not yet arrived) has no peak between its samples:
    # every one of its samples would be a candidate, 10^7 intervals in a 10,000-DOF run
    candidate &= (inner > magnitude[:, :-2]) | (inner > magnitude[:, 2:])
    j, at = np.nonzero(candidate)
    at = at + 1
    for end, other in ((0, 1), (N - 1, N - 2)):  # an end sample that is the largest near it
        edge = np.flatnonzero((magnitude[:, end] >= (1 - NEAR) * peaks) & (magnitude[:, end] > magnitude[:, other]))
        j, at = np.concatenate([j, edge]), np.concatenate([at, np.full(len(edge), end)])
    k = np.concatenate([at - 1, at])
    j = np.concatenate([j, j])
    inside = (k >= 0) & (k < N - 1)
    k, j = k[inside], j[inside]
    k, j = k[usable[k]], j[usable[k]]
    ends = (x[j, k], v[j, k], a[j, k], x[j, k + 1], v[j, k + 1], a[j, k + 1])
    finite = np.logical_and.reduce([np.isfinite(q) for q in ends]) if len(k) else np.zeros(0, dtype=bool)
    if not finite.any():
        return done()
    k, j = k[finite], j[finite]
    found, at = _interval_peaks(*(q[finite] for q in ends), time[k + 1] - time[k])
    found = np.where(np.isnan(found), 0.0, found)
    if with_times:  # each history's best interval, where it beats the samples
        order = np.lexsort((found, j))
        last = order[np.r_[j[order][1:] != j[order][:-1], True]]
        better = found[last] > peaks[j[last]]
        chosen = last[better]
        when[j[chosen]] = time[k[chosen]] + at[chosen] * (time[k[chosen] + 1] - time[k[chosen]])
    np.maximum.at(peaks, j, found)
    return done()


def local_peaks(time: np.ndarray, x: np.ndarray, v: np.ndarray | None, a: np.ndarray | None,
                events: np.ndarray = np.empty(0), count: int = 8, v_left: np.ndarray | None = None,
                a_left: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The count largest local maxima in time of |x| (one history, (N,) each), each located between its samples as
    located_peaks locates the largest (v, a None: the samples' own); v_left, a_left the left limits where they
    differ: (values, times), largest first. The pieces of a largest-peak objective, each smooth in the parameters
    where the largest itself has a kink (two peaks in time trading places)."""
    magnitude = np.abs(np.nan_to_num(x))
    N = len(time)
    if N < 3:
        k = int(np.argmax(magnitude)) if N else 0
        return (magnitude[k:k + 1].copy(), time[k:k + 1].copy()) if N else (np.zeros(0), np.zeros(0))
    inner = magnitude[1:-1]
    turn = (inner >= magnitude[:-2]) & (inner >= magnitude[2:]) & ((inner > magnitude[:-2]) | (inner > magnitude[2:]))
    at = np.flatnonzero(turn) + 1
    ends = [e for e, o in ((0, 1), (N - 1, N - 2)) if magnitude[e] > magnitude[o]]
    at = np.concatenate([at, np.array(ends, dtype=int)])
    if not len(at):
        k = int(np.argmax(magnitude))
        return magnitude[k:k + 1].copy(), time[k:k + 1].copy()
    at = at[np.argsort(-magnitude[at], kind="stable")[:count]]
    values, times = magnitude[at].copy(), time[at].copy()
    usable = np.ones(N - 1, dtype=bool)
    if len(events):
        usable[np.clip(np.searchsorted(time, events, side="right") - 1, 0, N - 2)] = False
        usable[np.clip(np.searchsorted(time, events, side="left") - 1, 0, N - 2)] = False
    v_end, a_end = (v if v_left is None else v_left), (a if a_left is None else a_left)
    for side in (-1, 0) if v is not None else ():  # the interval before each sample, then the one after
        k = at + side
        inside = (k >= 0) & (k < N - 1)
        inside[inside] &= usable[k[inside]]
        if not inside.any():
            continue
        k = k[inside]
        found, s = _interval_peaks(x[k], v[k], a[k], x[k + 1], v_end[k + 1], a_end[k + 1], time[k + 1] - time[k])
        better = np.nan_to_num(found, nan=-1.0) > values[inside]
        rows = np.flatnonzero(inside)[better]
        values[rows] = found[better]
        times[rows] = time[k[better]] + s[better] * (time[k[better] + 1] - time[k[better]])
    order = np.argsort(-values, kind="stable")
    return values[order], times[order]


def jump_times(model, grid: np.ndarray) -> np.ndarray:
    """Where a scene's acceleration or state jumps within the grid: its forces' discontinuities (a kink leaves the
    acceleration continuous) and the ground's jumps."""
    times = [float(t) for t, _, _ in model.jumps]
    for signal in model.signals:
        at = signal.breakpoints(float(grid[0]), float(grid[-1]))
        times += [float(t) for t in at[signal.value(at) != signal.value_left(at)]]
    return np.array(times, dtype=float)


def result_peaks(result, absolute: bool = False) -> np.ndarray:
    """Each DOF's largest |x| (relative, or absolute under ground motion), located between the samples and at the
    events (a yield's corner, a stop's contact point: where the samples cut the corner)."""
    quantities = [result.absolute(q) if absolute else getattr(result, q)
                  for q in ("displacement", "velocity", "acceleration")]
    # where the acceleration or the state jumps (events, a force's discontinuities, the ground's jumps) the
    # interpolant does not hold: those intervals keep their samples, and the events' own states join them
    events = [t for t, _, _ in result.nonsmooth.events] if result.nonsmooth is not None else []
    if result.origin is not None and len(result.time) > 1:
        events += list(jump_times(result.origin[1], result.time))
    peaks = located_peaks(result.time, *quantities, events=np.array(events, dtype=float))
    if result.nonsmooth is not None:
        t_event, x_event, _, _ = result.nonsmooth.event_state()
        if len(t_event):
            if absolute and result.ground is not None:  # the ground's displacement at the events, on its quintic
                g = result.ground
                x_event = x_event + quintic_at(result.time, g.displacement, g.velocity, g.acceleration,
                                               t_event)[:, None]
            peaks = np.fmax(peaks, np.abs(x_event).max(axis=0))
    return peaks


def drifts(q: np.ndarray, chain: list[int]) -> np.ndarray:
    """(N, S) storey drifts of (N, n) histories: each chain mass less the one below (the ground's zero)."""
    upper = q[:, chain]
    lower = np.concatenate([np.zeros((len(q), 1)), upper[:, :-1]], axis=1)
    return upper - lower


def located_drifts(result, model, chain: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(peak |drift| (S,), when, the events and jumps the interpolant stops at) of a solved run: located between
    samples on the quintic, and at the events' own states (a yielding storey's peak is at its unloading)."""
    d, v, a = (drifts(q, chain) for q in (result.displacement, result.velocity, result.acceleration))
    events = [t for t, _, _ in result.nonsmooth.events] if result.nonsmooth is not None else []
    events = np.concatenate([np.asarray(events, dtype=float), jump_times(model, result.time)])
    peak, at = located_peaks(result.time, d, v, a, events, with_times=True)
    if result.nonsmooth is not None:
        t_event, x_event, _, _ = result.nonsmooth.event_state()
        if len(t_event):
            at_events = np.abs(drifts(x_event, chain))
            best = np.argmax(at_events, axis=0)
            largest = at_events[best, np.arange(len(chain))]
            at = np.where(largest > peak, t_event[best], at)
            peak = np.fmax(peak, largest)
    return peak, at, events
