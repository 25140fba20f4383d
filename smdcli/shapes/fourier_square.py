"""`type = "fourier_square"`: the book's func_pulse, a square wave's truncated Fourier series.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.shapes.base import Exo, Signal, read_omega

FOURIER_SQUARE = 6  # compiled row kind
MAX_TERMS = 10_000


class FourierSquare(Signal):
    """The book's func_pulse: sum over n = 1..terms of (2A/(n pi))(1 - cos n pi) sin(n omega (t - t0)); its
    derivatives (a ground displacement's velocity and acceleration) are the same series with other coefficients
    and every phase advanced by `phase`."""

    types = ("fourier_square",)
    fields = ("amplitude", "omega", "frequency", "period", "terms", "t0")
    kinds = (FOURIER_SQUARE,)

    def __init__(self, amplitude: float, omega: float, terms: int, t0: float):
        self.omega, self.t0, self.phase = omega, t0, 0.0
        n = np.arange(1, terms + 1)
        with np.errstate(over="ignore", invalid="ignore"):  # an amplitude near 1e308: NaN, which the caller refuses
            coef = 2 * amplitude / (n * math.pi) * (1 - np.cos(n * math.pi))
        keep = np.abs(coef) > 1e-14 * abs(amplitude)  # even harmonics vanish
        self.harmonics = n[keep].astype(float)
        self.coefs = coef[keep]

    @classmethod
    def read(cls, t):
        spec = {"amplitude": t.number("amplitude"), "t0": t.number("t0", 0.0),
                "omega": read_omega(t, allow_period=True), "terms": t.integer("terms", minimum=1)}
        if spec["terms"] > MAX_TERMS:
            raise t.fail("terms", f"expected at most {MAX_TERMS} harmonics, found {spec['terms']}")
        return spec

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.amplitude, spec.omega, spec.terms, spec.t0)

    def derivative(self, start):
        derived = FourierSquare.__new__(FourierSquare)
        derived.omega, derived.t0, derived.harmonics = self.omega, self.t0, self.harmonics
        derived.coefs = self.coefs * self.harmonics * self.omega
        derived.phase = self.phase + math.pi / 2
        return derived

    def phase_origin(self):
        return self.t0

    def harmonic_terms(self):
        w = self.harmonics * self.omega
        return w, np.asarray(self.coefs, dtype=float), self.phase - w * self.t0

    @property
    def period(self):
        return 2 * math.pi / self.omega

    def value(self, t):
        t = np.asarray(t, dtype=float)
        flat = t.ravel()
        out = np.empty(flat.shape)
        block = max(1, 2**21 // max(len(self.harmonics), 1))  # times x harmonics held at once: 16 MB at most
        with np.errstate(over="ignore", invalid="ignore"):  # non-finite values are refused by the caller, silently
            for lo in range(0, len(flat), block):
                arg = np.multiply.outer(flat[lo:lo + block] - self.t0, self.harmonics * self.omega) + self.phase
                out[lo:lo + block] = np.sin(arg) @ self.coefs
        return out.reshape(t.shape)

    def exo(self):
        m = len(self.harmonics)
        S = np.zeros((2 * m, 2 * m))
        g = np.zeros(2 * m)
        for i, (n, c) in enumerate(zip(self.harmonics, self.coefs)):
            w = n * self.omega
            S[2 * i, 2 * i + 1], S[2 * i + 1, 2 * i] = w, -w
            g[2 * i] = c
        return Exo(S, g)

    def exo_state(self, t):
        arg = self.harmonics * self.omega * (t - self.t0) + self.phase
        out = np.empty(2 * len(arg))
        out[0::2], out[1::2] = np.sin(arg), np.cos(arg)
        return out

    def exo_states(self, t):
        arg = np.multiply.outer(np.asarray(t, dtype=float) - self.t0, self.harmonics * self.omega) + self.phase
        out = np.empty((len(arg), 2 * arg.shape[1]))
        out[:, 0::2], out[:, 1::2] = np.sin(arg), np.cos(arg)
        return out

    def kernel_row(self):
        return FOURIER_SQUARE, [self.omega, self.t0, self.phase], [*self.harmonics, *self.coefs], []
