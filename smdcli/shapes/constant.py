"""`type = "constant"`: amplitude for all time.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import numpy as np

from smdcli.shapes.base import Exo, Signal

CONSTANT = 0  # compiled row kind


class Constant(Signal):
    """amplitude, always."""

    types = ("constant",)
    scaled_by_amplitude = True
    fields = ("amplitude",)
    kinds = (CONSTANT,)

    def __init__(self, amplitude: float):
        self.amplitude = amplitude

    @classmethod
    def read(cls, t):
        return {"amplitude": t.number("amplitude")}

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.amplitude)

    def value(self, t):
        return np.full(np.shape(t), self.amplitude)

    def exo(self):
        return Exo(np.zeros((1, 1)), np.array([self.amplitude]))

    def exo_state(self, t):
        return np.ones(1)

    def exo_states(self, t):
        return np.ones((len(t), 1))

    def derivative(self, start):
        return None

    def kernel_row(self):
        return CONSTANT, [self.amplitude], [], []
