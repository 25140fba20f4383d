"""`type = "chirp"`: a linear frequency sweep. No exact generator: the exact solver samples it.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.shapes.base import Signal
from smdcli.shapes.expression import ExpressionSignal

CHIRP = 7  # compiled row kind


class Chirp(Signal):
    """amplitude * sin(2 pi (f0 t + (f1 - f0) t^2 / (2 t1)) + phase): linear sweep f0 -> f1 [Hz] at t1."""

    types = ("chirp",)
    fields = ("amplitude", "f0", "f1", "t1", "phase")
    kinds = (CHIRP,)
    exact = False
    series = False

    def __init__(self, amplitude, f0, f1, t1, phase):
        self.amplitude, self.f0, self.rate, self.phase = amplitude, f0, (f1 - f0) / t1, phase

    @classmethod
    def read(cls, t):
        return {"amplitude": t.number("amplitude"), "f0": t.number("f0", minimum=0.0),
                "f1": t.number("f1", minimum=0.0), "t1": t.number("t1", positive=True),
                "phase": t.number("phase", 0.0)}

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.amplitude, spec.f0, spec.f1, spec.t1, spec.phase)

    @classmethod
    def resolution_problem(cls, spec, start, end, step):
        """A sweep whose frequency passes the output grid's Nyquist frequency cannot be seen or held."""
        rate = (spec.f1 - spec.f0) / spec.t1
        if not math.isfinite(rate):
            return "t1", (f"the chirp's sweep rate (f1 - f0) / t1 overflows (t1 = {spec.t1:g} s); the force cannot "
                          "be resolved")
        top = max(abs(spec.f0 + rate * start), abs(spec.f0 + rate * end))  # Hz; it sweeps on past t1
        if top * step <= 0.5:
            return None
        need = 0.5 / top if top > 0 else math.inf
        return "f1", (f"the chirp reaches {top:.4g} Hz by t = {end:g} s, above the output grid's Nyquist frequency "
                      f"{0.5 / step:.4g} Hz (step {step:.3g} s); the force cannot be resolved: use a [time] step of "
                      f"at most {need:.3g} s, or lower f1 or t1")

    def value(self, t):
        t = np.asarray(t, dtype=float)
        return self.amplitude * np.sin(2 * math.pi * (self.f0 * t + 0.5 * self.rate * t * t) + self.phase)

    def derivative(self, start):
        """Differentiated as the expression it is."""
        text = (f"{self.amplitude!r} * sin(2 * pi * ({self.f0!r} * t + 0.5 * {self.rate!r} * t ** 2) + "
                f"{self.phase!r})")
        return ExpressionSignal(text).derivative(start)

    def kernel_row(self):
        return CHIRP, [self.amplitude, self.f0, self.rate, self.phase], [], []
