"""`type = "square"`: the exact square wave, +amplitude for the first `duty` of each period from t0.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.shapes.base import EDGE_SNAP, Exo, Signal, read_omega

SQUARE = 5  # compiled row kind


class Square(Signal):
    """The exact square wave: +amplitude for the first `duty` of each period from t0, -amplitude after."""

    types = ("square",)
    scaled_by_amplitude = True
    fields = ("amplitude", "omega", "frequency", "period", "duty", "t0")
    kinds = (SQUARE,)

    def __init__(self, amplitude: float, omega: float, duty: float, t0: float):
        self.amplitude, self._period, self.duty, self.t0 = amplitude, 2 * math.pi / omega, duty, t0

    @classmethod
    def read(cls, t):
        spec = {"amplitude": t.number("amplitude"), "t0": t.number("t0", 0.0),
                "omega": read_omega(t, allow_period=True)}
        duty = t.number("duty", 0.5)
        if not 0.0 < duty < 1.0:
            raise t.fail("duty", f"expected a fraction between 0 and 1 (exclusive), found {duty:g}")
        return spec | {"duty": duty}

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.amplitude, spec.omega, spec.duty, spec.t0)

    @property
    def period(self):
        return self._period

    def _phase(self, t):
        p = (np.asarray(t, dtype=float) - self.t0) / self._period
        p = p - np.floor(p)
        p = np.where(p > 1 - EDGE_SNAP, 0.0, p)  # just before a period start counts as on it
        return np.where(np.abs(p - self.duty) < EDGE_SNAP, self.duty, p)

    def value(self, t):
        return np.where(self._phase(t) < self.duty, self.amplitude, -self.amplitude)

    def value_left(self, t):
        p = self._phase(t)
        return np.where((p > 0) & (p <= self.duty), self.amplitude, -self.amplitude)

    def edge_count(self, t0: float, t1: float, limit: int | None = None) -> float:
        """About how many edges fall in [t0, t1], without listing them."""
        return 2 * (t1 - t0) / self._period + 4

    def breakpoints(self, t0, t1):
        T = self._period
        k0 = math.floor((t0 - self.t0) / T) - 1
        k1 = math.ceil((t1 - self.t0) / T) + 1
        ks = np.arange(k0, k1 + 1)
        edges = np.concatenate([self.t0 + ks * T, self.t0 + (ks + self.duty) * T])
        edges.sort()
        return edges[(edges > t0) & (edges < t1)]

    def exo(self):
        return Exo(np.zeros((1, 1)), np.array([self.amplitude]))

    def exo_state(self, t):
        return np.array([1.0 if float(self._phase(t)) < self.duty else -1.0])

    def derivative(self, start):
        return None

    def kernel_row(self):
        return SQUARE, [self.amplitude, self._period, self.duty, self.t0], [], []
