"""Storey measures of a building's run ([building] storey_heights): each storey's drift (the mass's displacement
less the one below, the ground's zero: relative to the support under ground motion), drift ratio (over its height)
and shear (the tensions of the elements joining the storey's two levels: its springs, dampers, friction contacts
and stops, positive when it pulls the upper mass down), their peaks located between samples, and the residual
drift at the run's end.

A drift's peak is located on the quintic Hermite of the drift, its velocity and acceleration (as a displacement's
peak is), and at the events' own states: a yielding storey's peak drift is where it unloads, an event the samples
cut the corner of (a grid of 0.02 s read a bilinear frame's third storey 0.9 % short); a shear's where the
storey's elements are linear springs and dampers, on k d(t) + c d'(t) of that same quintic; a storey holding a nonlinear element, or a step holding an event, keeps its samples' shear.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from smdcli.scenario.spec import GROUND

SEEDS = 33  # points a step's shear polynomial is first read at, then refined by Newton's method on its slope


@dataclass(frozen=True)
class Storeys:
    """A run's storey measures: (N, S) histories, (S,) peaks and where they are."""

    names: tuple[str, ...]  # each storey by its upper mass
    heights: np.ndarray
    drift: np.ndarray  # (N, S) m
    drift_ratio: np.ndarray  # (N, S)
    shear: np.ndarray  # (N, S) N
    peak_drift: np.ndarray  # (S,) m, located
    peak_drift_time: np.ndarray
    peak_drift_ratio: np.ndarray
    peak_shear: np.ndarray  # (S,) N
    peak_shear_time: np.ndarray
    residual_drift: np.ndarray  # (S,) m
    shear_located: np.ndarray  # (S,) bool: whether the storey's shear peak is located (linear elements only)


def storeys(result, building) -> Storeys:
    """The storey measures of a solved run (Result with its element forces) of a scene with [building]."""
    from smdcli.solvers.peaks import drifts, located_drifts

    model = result.origin[1]
    index = {name: i for i, name in enumerate(result.dofs)}
    chain = [index[name] for name in building.masses]
    heights = np.asarray(building.storey_heights, dtype=float)

    d, v, a = (drifts(q, chain) for q in (result.displacement, result.velocity, result.acceleration))
    peak, at, events = located_drifts(result, model, chain)
    levels = [GROUND] + list(building.masses)
    shear = np.zeros_like(d)
    linear = np.ones(len(chain), dtype=bool)
    k_sum, c_sum = np.zeros(len(chain)), np.zeros(len(chain))
    forces = result.elements
    laws = {e.name: e for e in model.elements}
    for values, names, connects in _element_sets(forces):
        for j, (name, ends) in enumerate(zip(names, connects)):
            for s in range(len(chain)):
                if set(ends) != {levels[s], levels[s + 1]}:
                    continue
                shear[:, s] += values[:, j]
                element = laws.get(name)  # a hysteretic spring, a contact or a stop is not: a nonlinear storey
                if element is None or element.law != "linear":
                    linear[s] = False
                elif element.kind == "spring":
                    k_sum[s] += element.coef
                else:
                    c_sum[s] += element.coef
    magnitude = np.abs(shear)
    shear_peak = magnitude.max(axis=0) if len(shear) else np.zeros(len(chain))
    shear_at = result.time[np.argmax(magnitude, axis=0)] if len(shear) else np.zeros(len(chain))
    for s in np.flatnonzero(linear):
        shear_peak[s], shear_at[s] = _linear_peak(result.time, d[:, s], v[:, s], a[:, s], k_sum[s], c_sum[s],
                                                  events, shear_peak[s], shear_at[s])
    return Storeys(tuple(building.masses), heights, d, d / heights, shear, peak, at, peak / heights, shear_peak,
                   shear_at, d[-1].copy(), linear)


def _element_sets(forces):
    """(values (N, E), names, connects) of each kind of element the run's forces hold."""
    yield forces.spring, forces.spring_names, forces.spring_connects
    yield forces.damper, forces.damper_names, forces.damper_connects
    if forces.friction is not None:
        yield forces.friction, forces.friction_names, forces.friction_connects
    if forces.stop is not None:
        yield forces.stop, forces.stop_names, forces.stop_connects


def _linear_peak(time, d, v, a, k: float, c: float, events, best: float, best_at: float) -> tuple[float, float]:
    """The largest |k d(t) + c d'(t)| on the quintic Hermite of d in the steps around the samples' largest (steps
    holding an event keep their samples), refined by Newton's method on its slope."""
    from smdcli.solvers.peaks import quintic_coefficients

    shear = np.abs(k * d + c * v)
    N = len(time)
    if N < 2:
        return best, best_at
    top = int(np.argmax(shear))
    for step in (top - 1, top):
        if not 0 <= step < N - 1 or ((events > time[step]) & (events < time[step + 1])).any():
            continue
        h = time[step + 1] - time[step]
        q = quintic_coefficients(d[step], v[step], a[step], d[step + 1], v[step + 1], a[step + 1], h)
        derivative = np.array([q[1], 2 * q[2], 3 * q[3], 4 * q[4], 5 * q[5], 0.0]) / h
        p = np.polynomial.Polynomial(k * q + c * derivative)  # the shear in s = (t - t_step) / h
        grid = np.linspace(0.0, 1.0, SEEDS)
        s = grid[int(np.argmax(np.abs(p(grid))))]
        slope, curvature = p.deriv(), p.deriv(2)
        for _ in range(6):
            if curvature(s) == 0:
                break
            s = float(np.clip(s - slope(s) / curvature(s), 0.0, 1.0))
        if abs(p(s)) > best:
            best, best_at = abs(float(p(s))), float(time[step] + s * h)
    return best, best_at
