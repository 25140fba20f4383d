"""`type = "sine"` and `type = "cosine"`: amplitude sin(omega t + phase), or cos.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.shapes.base import Exo, Signal, read_omega

SINE, COSINE = 3, 4  # compiled row kinds


class Harmonic(Signal):
    """amplitude * sin(omega t + phase), or cos for `cosine`."""

    types = ("sine", "cosine")
    fields = ("amplitude", "omega", "frequency", "phase")
    kinds = (SINE, COSINE)

    def __init__(self, amplitude: float, omega: float, phase: float, cosine: bool):
        self.amplitude, self.omega, self.phase, self.cosine = amplitude, omega, phase, cosine

    @classmethod
    def read(cls, t):
        return {"amplitude": t.number("amplitude"), "omega": read_omega(t, allow_period=False),
                "phase": t.number("phase", 0.0)}

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.amplitude, spec.omega, spec.phase, cosine=(spec.type == "cosine"))

    def value(self, t):
        with np.errstate(over="ignore", invalid="ignore"):  # a phase past 1e308 is NaN, which the caller refuses
            arg = self.omega * np.asarray(t, dtype=float) + self.phase
            return self.amplitude * (np.cos(arg) if self.cosine else np.sin(arg))

    def exo(self):
        w = self.omega
        g = np.array([0.0, self.amplitude]) if self.cosine else np.array([self.amplitude, 0.0])
        return Exo(np.array([[0.0, w], [-w, 0.0]]), g)

    def exo_state(self, t):
        arg = self.omega * t + self.phase
        return np.array([math.sin(arg), math.cos(arg)])

    def exo_states(self, t):
        arg = self.omega * np.asarray(t, dtype=float) + self.phase
        return np.stack([np.sin(arg), np.cos(arg)], axis=1)

    def derivative(self, start):
        return Harmonic(self.amplitude * self.omega, self.omega, self.phase + math.pi / 2, self.cosine)

    def harmonic_terms(self):
        shift = math.pi / 2 if self.cosine else 0.0
        return np.array([self.omega]), np.array([self.amplitude]), np.array([self.phase + shift])

    @property
    def period(self):
        return 2 * math.pi / self.omega if self.omega > 0 else None

    def kernel_row(self):
        return (COSINE if self.cosine else SINE), [self.amplitude, self.omega, self.phase], [], []
