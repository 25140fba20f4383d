"""A force's derivative along a parameter, as the sensitivity system takes it: a number times the force where it is
that (an amplitude, a record's scale), else a signal of its own (the stencil's combination of the force at its
points, with a generator beside the force's).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.shapes.base import Exo, Signal
from smdcli.shapes.table import Table


def combined(weights: np.ndarray, values) -> np.ndarray:
    """sum w_k f_k as differences from the first value (Derivative.of's rule)."""
    return sum(w * (v - values[0]) for w, v in zip(weights[1:], values[1:]))


def stencil_total(stencil: tuple, scale: float, read) -> np.ndarray:
    """scale times the total derivative along a parameter of read(scene, c): stencil (its scenes, offsets in the
    parameter's units, weights times scale), read at each scene and c = offset / scale, what a sensitivity scaled by
    scale is multiplied by to move a quantity with the parameter to that point (the event runs')."""
    scenes, offsets, weights = stencil
    return combined(weights, [np.asarray(read(scene, o / scale), dtype=float) for scene, o in zip(scenes, offsets)])


def shifted_stencil_total(stencil: tuple, scale: float, read) -> np.ndarray:
    """stencil_total of a read at the state moved with the parameter (y + c s, read(scene, c) honouring c at every
    point): an affine parameter's one difference (p, p + d) is read at both shifts, [(r(p + d, c) + r(p + d, -c)) / 2
    - r(p, -c)] / d, exact where the read is affine in p and holds p times the state (a damper's c in a held
    contact's force, c v: the one-sided difference kept half its second derivative, dt*/dc of a breakaway 1.4 %
    off); a stencil of more points as stencil_total."""
    scenes, offsets, weights = stencil
    if len(scenes) != 2 or offsets[0] != 0:
        return stencil_total(stencil, scale, read)
    c = offsets[1] / scale
    ahead, behind = (np.asarray(read(scenes[1], side * c), dtype=float) for side in (1.0, -1.0))
    return weights[1] * ((ahead + behind) / 2 - np.asarray(read(scenes[0], -c), dtype=float))


class ParameterDerivative(Signal):
    """du/dp of a force as a signal: the stencil's combination of the force at its points; its generator the
    force's with the derivative's beside it, [[S, 0], [dS, S]] on [w; dw], read as dg w + g dw. Where S moves with p
    (a frequency), dw is the generator's own flow from where its state holds still (anchors: the phase's origin, the
    last breakpoint), not the points' states combined at t, whose error grows as (delta t)^4 (4e-4 of the book's
    three-DOF scene's forcing frequency at 120 s)."""

    exact = True

    def __init__(self, base: Signal, points: list[Signal], weights: np.ndarray):
        self.base, self.points, self.weights = base, points, weights
        self._exo = self._flows = self._commute = None
        self._still: dict[bytes, bool] = {}  # whether dw holds still at these anchors, by the anchors' bytes

    def value(self, t):
        if not self.flows():
            return combined(self.weights, [s.value(t) for s in self.points])
        times = np.atleast_1d(np.asarray(t, dtype=float))
        found = self._commuting(times)
        if found is None:
            return np.reshape(self._states(times) @ self.exo().g, np.shape(t))
        w, tau, moved = found  # [w; tau dS w] . [dg; g], the states not formed (the grid's forces: 3x the speed)
        dg, g = np.split(self.exo().g, 2)
        return np.reshape(w @ dg + tau * (w @ (moved.T @ g)), np.shape(t))

    def value_left(self, t):
        if not self.flows():
            return combined(self.weights, [s.value_left(t) for s in self.points])
        times = np.atleast_1d(np.asarray(t, dtype=float))
        return np.reshape(self._states(times, left=True) @ self.exo().g, np.shape(t))

    def breakpoints(self, t0, t1):
        return self.base.breakpoints(t0, t1)

    def phase_origin(self):
        return self.base.phase_origin()

    def exo(self):
        if self._exo is None:
            exo = self.base.exo()
            if exo is None:
                return None
            m = exo.S.shape[0]
            S = np.zeros((2 * m, 2 * m))
            S[:m, :m] = S[m:, m:] = exo.S
            S[m:, :m] = combined(self.weights, [s.exo().S for s in self.points])
            dg = combined(self.weights, [s.exo().g for s in self.points])
            self._exo = Exo(S, np.concatenate([dg, exo.g]))
        return self._exo

    def flows(self) -> bool:
        """Whether the generator's matrix moves with p, so that its state's derivative is its flow's."""
        if self._flows is None:
            exo = self.exo()
            self._flows = exo is not None and bool(exo.S[len(exo.S) // 2:, :len(exo.S) // 2].any())
        return self._flows

    def exo_state(self, t):
        return self.exo_states(np.array([float(t)]))[0]

    def exo_states(self, t):
        times = np.asarray(t, dtype=float)
        if not self.flows():
            return np.concatenate([self.base.exo_states(times),
                                   combined(self.weights, [s.exo_states(times) for s in self.points])], axis=1)
        return self._states(times)

    def _states(self, times: np.ndarray, left: bool = False) -> np.ndarray:
        """[w; dw] just after (left: just before) each time, by the flow of [[S, 0], [dS, S]] from its anchor."""
        found = self._commuting(times, left)
        if found is not None:
            w, tau, moved = found
            return np.concatenate([w, tau[:, None] * (w @ moved.T)], axis=1)
        from scipy.linalg import expm

        S = self.exo().S
        marks, which = anchor_marks(self.base, times, left)
        held = combined(self.weights, [s.exo_states(marks) for s in self.points])
        seeds = np.concatenate([self.base.exo_states(marks), held], axis=1)[which]
        return np.array([expm(S * step) @ seed for step, seed in zip(times - marks[which], seeds)])

    def _commuting(self, times: np.ndarray, left: bool = False) -> tuple | None:
        """(w, tau, dS) with dw = tau dS w at each time (tau: from its anchor), where dS commutes with S and dw holds
        still at the anchor (d/dp exp(S tau) w = tau dS exp(S tau) w: a frequency's); else None (just before each
        time, left: None)."""
        S = self.exo().S
        m = len(S) // 2
        own, moved = S[:m, :m], S[m:, :m]
        if self._commute is None:
            scale = 1e-14 * np.abs(own).max() * np.abs(moved).max()
            self._commute = bool(np.abs(own @ moved - moved @ own).max() <= scale)
        if left or not self._commute:
            return None
        marks, which = anchor_marks(self.base, times, left)  # few anchors (a harmonic's one origin), many times
        still = self._still.get(key := marks.tobytes())
        if still is None:  # asked once per anchors: a run asks at every block's start and for the grid's forces
            still = self._still[key] = not combined(self.weights, [s.exo_states(marks) for s in self.points]).any()
        if not still:
            return None
        return self.base.exo_states(times), times - marks[which], moved

    def derivative(self, start):
        base = self.base.derivative(start)
        if base is None:
            return None
        return ParameterDerivative(base, [s.derivative(start) for s in self.points], self.weights)


def anchors(signal: Signal, times: np.ndarray, left: bool = False) -> np.ndarray:
    """Where the generator's state holds still before each time: its last breakpoint at or before it (before it:
    left), else the phase's origin (backwards too, where no breakpoint lies between), else the time itself."""
    marks, which = anchor_marks(signal, times, left)
    return marks[which]


def anchor_marks(signal: Signal, times: np.ndarray, left: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """anchors(signal, times, left) as (the anchors there are, each time's index into them)."""
    times = np.asarray(times, dtype=float)
    if not len(times):
        return times, np.zeros(0, dtype=int)
    origin = signal.phase_origin()
    edges = np.asarray(signal.breakpoints(min(float(times.min()), origin) - 1.0, float(times.max()) + 1.0), dtype=float)
    marks = np.union1d(edges, [origin]) if len(edges) else np.array([origin])  # a harmonic's: its origin alone
    i = np.searchsorted(marks, times, side="left" if left else "right") - 1
    if marks[0] == origin or i.min() >= 0:
        return marks, np.maximum(i, 0)
    before = i < 0  # no breakpoint or origin before them: each its own anchor
    return np.concatenate([marks, times[before]]), np.where(before, len(marks) + np.cumsum(before) - 1, i)


def signal_derivative(base: Signal, d, j: int) -> Signal | float | None:
    """du_j/dp as a signal, or as a number times u_j where it is that (an amplitude, a record's scale: no second
    signal with its own generator states), None where the force does not depend on p; d: the parameter's
    model_derivative.Derivative (its models and weights)."""
    points = [m.signals[j] for m in d.models]
    if isinstance(base, Table):
        dv = combined(d.weights, [s.v for s in points])
        if not np.any(dv):
            return None
        factor = _proportion(base.v, dv)
        return factor if factor is not None else Table(base.t, dv, "previous" if base.previous else "linear",
                                                       ended=base.ended)
    if all(_same_signal(base, s) for s in points):
        return None
    ratios = [s.ratio_to(base) for s in points]
    if all(r is not None for r in ratios):  # an amplitude moved: u times its weighed ratios
        return float(np.dot(d.weights, ratios))
    terms, others = base.harmonic_terms(), [s.harmonic_terms() for s in points]
    if terms is not None and all(o is not None and np.array_equal(o[0], terms[0]) and np.array_equal(o[2], terms[2])
                                 for o in others):  # sum c_k sin(w_k t + p_k) with the same w and p: c moved
        factors = [_proportion(terms[1], o[1]) for o in others]
        if all(f is not None for f in factors):
            return float(np.dot(d.weights, factors))
    return ParameterDerivative(base, points, d.weights)


def _proportion(base: np.ndarray, other: np.ndarray) -> float | None:
    """c where other = c base to rounding (1e-14 of other's largest), else None."""
    base, other = np.ravel(base), np.ravel(other)
    norm = float(base @ base)
    if norm == 0:
        return None
    factor = float(base @ other) / norm
    return factor if np.abs(other - factor * base).max() <= 1e-14 * np.abs(other).max(initial=0.0) else None


def _same_signal(a: Signal, b: Signal) -> bool:
    if a is b:  # a model moved along another parameter keeps its forces (model/moved.py)
        return True
    ea, eb = a.exo(), b.exo()
    if ea is None or eb is None:
        return type(a) is type(b) and vars(a).keys() == vars(b).keys() and all(
            np.array_equal(np.asarray(x), np.asarray(y)) if isinstance(x, np.ndarray) else x == y
            for x, y in zip(vars(a).values(), vars(b).values()))
    return (np.array_equal(ea.S, eb.S) and np.array_equal(ea.g, eb.g)
            and np.array_equal(a.exo_state(0.0), b.exo_state(0.0)))
