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


class ParameterDerivative(Signal):
    """du/dp of a force as a signal: the stencil's combination of the force at its points; its generator the
    force's with the derivative's beside it, [[S, 0], [dS, S]] on [w; dw], read as dg w + g dw."""

    exact = True

    def __init__(self, base: Signal, points: list[Signal], weights: np.ndarray):
        self.base, self.points, self.weights = base, points, weights

    def value(self, t):
        return combined(self.weights, [s.value(t) for s in self.points])

    def value_left(self, t):
        return combined(self.weights, [s.value_left(t) for s in self.points])

    def breakpoints(self, t0, t1):
        return self.base.breakpoints(t0, t1)

    def exo(self):
        exo = self.base.exo()
        if exo is None:
            return None
        m = exo.S.shape[0]
        S = np.zeros((2 * m, 2 * m))
        S[:m, :m] = S[m:, m:] = exo.S
        S[m:, :m] = combined(self.weights, [s.exo().S for s in self.points])
        dg = combined(self.weights, [s.exo().g for s in self.points])
        return Exo(S, np.concatenate([dg, exo.g]))

    def exo_state(self, t):
        return np.concatenate([self.base.exo_state(t),
                               combined(self.weights, [s.exo_state(t) for s in self.points])])

    def derivative(self, start):
        base = self.base.derivative(start)
        if base is None:
            return None
        return ParameterDerivative(base, [s.derivative(start) for s in self.points], self.weights)


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
    ea, eb = a.exo(), b.exo()
    if ea is None or eb is None:
        return a is b or (type(a) is type(b) and vars(a).keys() == vars(b).keys() and all(
            np.array_equal(np.asarray(x), np.asarray(y)) if isinstance(x, np.ndarray) else x == y
            for x, y in zip(vars(a).values(), vars(b).values())))
    return (np.array_equal(ea.S, eb.S) and np.array_equal(ea.g, eb.g)
            and np.array_equal(a.exo_state(0.0), b.exo_state(0.0)))
