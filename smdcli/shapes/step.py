"""`type = "step"`: amplitude from t0 on.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import numpy as np

from smdcli.shapes.base import Exo, Signal

STEP = 1  # compiled row kind


class Step(Signal):
    """amplitude * Heaviside(t - t0), with Heaviside(0) = 1."""

    types = ("step",)
    scaled_by_amplitude = True
    fields = ("amplitude", "t0")
    kinds = (STEP,)

    def __init__(self, amplitude: float, t0: float):
        self.amplitude, self.t0 = amplitude, t0

    @classmethod
    def read(cls, t):
        return {"amplitude": t.number("amplitude"), "t0": t.number("t0", 0.0)}

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.amplitude, spec.t0)

    def value(self, t):
        return np.where(np.asarray(t) >= self.t0, self.amplitude, 0.0)

    def value_left(self, t):
        return np.where(np.asarray(t) > self.t0, self.amplitude, 0.0)

    def breakpoints(self, t0, t1):
        return np.array([self.t0]) if t0 < self.t0 < t1 else np.empty(0)

    def exo(self):
        return Exo(np.zeros((1, 1)), np.array([self.amplitude]))

    def exo_state(self, t):
        return np.array([1.0 if t >= self.t0 else 0.0])

    def exo_states(self, t):
        return (np.asarray(t, dtype=float) >= self.t0).astype(float)[:, None]

    def derivative(self, start):
        return None

    def kernel_row(self):
        return STEP, [self.amplitude, self.t0], [], []
