"""`type = "pulse"`: one shock pulse, zero outside [t0, t0 + duration]: the rectangle, half-sine, haversine and
triangle of the shock-test standards (MIL-STD-810 method 516, IEC 60068-2-27).

The rectangle, the half-sine and the haversine are, inside their window, c + a sin(w tau + q pi/2) with
tau = t - t0 and q a whole number of quarter turns: an exosystem of at most three states, so the exact solver
integrates them exactly, restarting at both edges; their derivatives (a ground displacement's velocity and
acceleration) are of the same form. Each edge's values use the exact sines of whole quarter turns: a half-sine
is exactly zero at its end (sin(pi) in floating point is 1.2e-16, which a ground displacement would read as a
jump). The triangle is a three-point table (zero, the peak at the middle, zero), linear between.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.shapes.base import Exo, Signal
from smdcli.shapes.table import Table

PULSE = 2  # compiled row kind
SHAPES = ("rectangle", "half_sine", "haversine", "triangle")
_SIN = (0.0, 1.0, 0.0, -1.0)  # sin(q pi/2) for q mod 4


def quarter_sin(x, q: int):
    """sin(x + q pi/2), with whole quarter turns taken exactly."""
    q %= 4
    return (np.sin(x), np.cos(x), -np.sin(x), -np.cos(x))[q]


class Pulse(Signal):
    """c + a sin(w (t - t0) + q pi/2) for t0 <= t < t_end, else 0; `turns` = w (t_end - t0) / pi, whole."""

    types = ("pulse",)
    fields = ("amplitude", "t0", "duration", "shape")
    kinds = (PULSE,)
    schema = {"shape": {"enum": list(SHAPES)}}
    shock = True

    def __init__(self, t0: float, t_end: float, c: float, a: float = 0.0, turns: int = 0, q: int = 0):
        self.t0, self.t_end, self.c, self.a, self.turns, self.q = t0, t_end, c, a, turns, q
        self.w = turns * math.pi / (t_end - t0)

    @classmethod
    def read(cls, t):
        spec = {"amplitude": t.number("amplitude"), "t0": t.number("t0", 0.0),
                "duration": t.number("duration", positive=True), "shape": t.string("shape", "rectangle",
                                                                                   choices=SHAPES)}
        if spec["t0"] + spec["duration"] == spec["t0"]:
            raise t.fail("duration", f"expected a duration that moves the time t0 = {spec['t0']:g} s, found "
                                     f"{spec['duration']:g} s, below its rounding ({math.ulp(spec['t0']):.3g} s)")
        return spec

    @classmethod
    def from_spec(cls, spec):
        A, t0, t_end = spec.amplitude, spec.t0, spec.t0 + spec.duration
        if spec.shape == "half_sine":  # A sin(pi tau / D)
            return cls(t0, t_end, 0.0, A, turns=1)
        if spec.shape == "haversine":  # A sin^2(pi tau / D) = A/2 - A/2 cos(2 pi tau / D)
            return cls(t0, t_end, A / 2, -A / 2, turns=2, q=1)
        if spec.shape == "triangle":
            return Table([t0, t0 + spec.duration / 2, t_end], [0.0, A, 0.0], "linear")
        return cls(t0, t_end, A)

    def _inside(self, t):
        return self.c + self.a * quarter_sin(self.w * (t - self.t0), self.q)

    def value(self, t):
        t = np.asarray(t, dtype=float)
        return np.where((t >= self.t0) & (t < self.t_end), self._inside(t), 0.0)

    def value_left(self, t):
        t = np.asarray(t, dtype=float)
        at_end = self.c + self.a * _SIN[(2 * self.turns + self.q) % 4]  # the exact limit at the end
        inside = np.where(t == self.t_end, at_end, self._inside(t))
        return np.where((t > self.t0) & (t <= self.t_end), inside, 0.0)

    def breakpoints(self, t0, t1):
        return np.array([b for b in (self.t0, self.t_end) if t0 < b < t1])

    def _parts(self) -> tuple[bool, bool]:
        """Whether the exosystem holds a constant state and a rotating pair."""
        return self.c != 0.0 or self.a == 0.0, self.a != 0.0

    def exo(self):
        constant, rotating = self._parts()
        size = constant + 2 * rotating
        S, g = np.zeros((size, size)), np.zeros(size)
        if constant:
            g[0] = self.c
        if rotating:
            i = int(constant)
            S[i, i + 1], S[i + 1, i] = self.w, -self.w
            g[i] = self.a
        return Exo(S, g)

    def exo_state(self, t):
        constant, rotating = self._parts()
        if not self.t0 <= t < self.t_end:
            return np.zeros(constant + 2 * rotating)
        x = self.w * (t - self.t0)
        pair = [float(quarter_sin(x, self.q)), float(quarter_sin(x, self.q + 1))] if rotating else []
        return np.array(([1.0] if constant else []) + pair)

    def derivative(self, start):
        if self.a == 0.0:
            return None
        return Pulse(self.t0, self.t_end, 0.0, self.a * self.w, self.turns, self.q + 1)

    def kernel_row(self):
        return PULSE, [self.t0, self.t_end], [self.c, self.a, self.w, float(self.q % 4)], []
