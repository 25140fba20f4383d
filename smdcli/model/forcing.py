"""Force signals: vectorized values, their discontinuity times, and exact forms.

A signal is *exactly integrable* when, between its breakpoints, it is the
output g.w(t) of a small linear system w' = S w (an "exosystem"): constants,
steps, harmonics, square waves, Fourier series and piecewise-linear tables.
The exact solver augments the structure's state with w and propagates both
with one matrix exponential, reseeding w from ``exo_state`` at every
breakpoint. Chirps and expressions have no such form.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from smdcli.scenario import ForceSpec

# Phase tolerance (in periods) within which a time counts as on a square
# wave's edge; breakpoints computed as t0 + k*T land within rounding of it.
_EDGE_SNAP = 1e-9


@dataclass(frozen=True)
class Exo:
    """Exosystem form: u(t) = g . w(t), w' = S w between breakpoints."""

    S: np.ndarray
    g: np.ndarray


class Signal:
    """A scalar force signal u(t) [N]."""

    exact = True

    def value(self, t):
        """Right-continuous value at t (array or scalar)."""
        raise NotImplementedError

    def value_left(self, t):
        """Left limit at t; equals value() where the signal is continuous."""
        return self.value(t)

    def breakpoints(self, t0: float, t1: float) -> np.ndarray:
        """Times in (t0, t1) where the signal or its slope jumps."""
        return np.empty(0)

    def edge_count(self, t0: float, t1: float, limit: int | None = None) -> float:
        """How many discontinuities fall in [t0, t1] (a signal with many overrides this to count without listing);
        past `limit` the count may stop early at any number above it."""
        return len(self.breakpoints(t0, t1))

    def exo(self) -> Exo | None:
        """The exosystem form, or None where the signal has none."""
        return None

    def exo_state(self, t: float) -> np.ndarray:
        """Exosystem state just after t."""
        raise NotImplementedError

    def exo_states(self, t: np.ndarray) -> np.ndarray:
        """exo_state at each of the times t, (len(t), its size)."""
        return np.array([self.exo_state(float(time)) for time in t]).reshape(len(t), -1)


class Constant(Signal):
    def __init__(self, amplitude: float):
        self.amplitude = amplitude

    def value(self, t):
        return np.full(np.shape(t), self.amplitude)

    def exo(self):
        return Exo(np.zeros((1, 1)), np.array([self.amplitude]))

    def exo_state(self, t):
        return np.ones(1)


class Step(Signal):
    """amplitude * Heaviside(t - t0), with Heaviside(0) = 1."""

    def __init__(self, amplitude: float, t0: float):
        self.amplitude, self.t0 = amplitude, t0

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


class Pulse(Signal):
    """amplitude for t0 <= t < t0 + duration, else 0."""

    def __init__(self, amplitude: float, t0: float, duration: float):
        self.amplitude, self.t0, self.t_end = amplitude, t0, t0 + duration

    def value(self, t):
        t = np.asarray(t)
        return np.where((t >= self.t0) & (t < self.t_end), self.amplitude, 0.0)

    def value_left(self, t):
        t = np.asarray(t)
        return np.where((t > self.t0) & (t <= self.t_end), self.amplitude, 0.0)

    def breakpoints(self, t0, t1):
        return np.array([b for b in (self.t0, self.t_end) if t0 < b < t1])

    def exo(self):
        return Exo(np.zeros((1, 1)), np.array([self.amplitude]))

    def exo_state(self, t):
        return np.array([1.0 if self.t0 <= t < self.t_end else 0.0])


class Harmonic(Signal):
    """amplitude * sin(omega t + phase), or cos for `cosine`."""

    def __init__(self, amplitude: float, omega: float, phase: float, cosine: bool):
        self.amplitude, self.omega, self.phase, self.cosine = amplitude, omega, phase, cosine

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


class Square(Signal):
    """The exact square wave: +amplitude for the first `duty` of each period from t0, -amplitude after."""

    def __init__(self, amplitude: float, omega: float, duty: float, t0: float):
        self.amplitude, self.period, self.duty, self.t0 = amplitude, 2 * math.pi / omega, duty, t0

    def _phase(self, t):
        p = (np.asarray(t, dtype=float) - self.t0) / self.period
        p = p - np.floor(p)
        p = np.where(p > 1 - _EDGE_SNAP, 0.0, p)  # just before a period start counts as on it
        return np.where(np.abs(p - self.duty) < _EDGE_SNAP, self.duty, p)

    def value(self, t):
        return np.where(self._phase(t) < self.duty, self.amplitude, -self.amplitude)

    def value_left(self, t):
        p = self._phase(t)
        return np.where((p > 0) & (p <= self.duty), self.amplitude, -self.amplitude)

    def edge_count(self, t0: float, t1: float, limit: int | None = None) -> float:
        """About how many edges fall in [t0, t1], without listing them."""
        return 2 * (t1 - t0) / self.period + 4

    def breakpoints(self, t0, t1):
        T = self.period
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


class FourierSquare(Signal):
    """The book's func_pulse: sum over n = 1..terms of (2A/(n pi))(1 - cos n pi) sin(n omega (t - t0)); its
    derivatives (a ground displacement's velocity and acceleration) are the same series with other coefficients
    and every phase advanced by `phase`."""

    def __init__(self, amplitude: float, omega: float, terms: int, t0: float):
        self.omega, self.t0, self.phase = omega, t0, 0.0
        n = np.arange(1, terms + 1)
        with np.errstate(over="ignore", invalid="ignore"):  # an amplitude near 1e308: NaN, which the caller refuses
            coef = 2 * amplitude / (n * math.pi) * (1 - np.cos(n * math.pi))
        keep = np.abs(coef) > 1e-14 * abs(amplitude)  # even harmonics vanish
        self.harmonics = n[keep].astype(float)
        self.coefs = coef[keep]

    def derivative(self) -> FourierSquare:
        """d/dt of the series, term by term."""
        derived = FourierSquare.__new__(FourierSquare)
        derived.omega, derived.t0, derived.harmonics = self.omega, self.t0, self.harmonics
        derived.coefs = self.coefs * self.harmonics * self.omega
        derived.phase = self.phase + math.pi / 2
        return derived

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


class Chirp(Signal):
    """amplitude * sin(2 pi (f0 t + (f1 - f0) t^2 / (2 t1)) + phase): linear sweep f0 -> f1 [Hz] at t1."""

    exact = False

    def __init__(self, amplitude, f0, f1, t1, phase):
        self.amplitude, self.f0, self.rate, self.phase = amplitude, f0, (f1 - f0) / t1, phase

    def value(self, t):
        t = np.asarray(t, dtype=float)
        return self.amplitude * np.sin(2 * math.pi * (self.f0 * t + 0.5 * self.rate * t * t) + self.phase)


class Table(Signal):
    """Tabulated force: linear interpolation (first-order hold) or previous value; the first value held before the
    table, the last held after it, or, `ended`, zero after the last sample (a record that is over: its last sample
    is its value there, the jump to zero its right limit, as exo_state gives it)."""

    def __init__(self, times, values, interpolation: str, ended: bool = False):
        self.t = np.asarray(times, dtype=float)
        self.v = np.asarray(values, dtype=float)
        self.previous = interpolation == "previous"
        self.ended = ended
        slopes = np.diff(self.v) / np.diff(self.t) if len(self.t) > 1 else np.empty(0)
        self.slopes = np.zeros_like(slopes) if self.previous else slopes

    def value(self, t):
        t = np.asarray(t, dtype=float)
        if self.previous:
            idx = np.searchsorted(self.t, t, side="right") - 1
            held = self.v[np.clip(idx, 0, None)]
        else:
            held = np.interp(t, self.t, self.v)
        return np.where(t > self.t[-1], 0.0, held) if self.ended else held

    def value_left(self, t):
        t = np.asarray(t, dtype=float)
        if not self.previous:
            held = np.interp(t, self.t, self.v)
        else:
            idx = np.searchsorted(self.t, t, side="left") - 1
            held = self.v[np.clip(idx, 0, None)]
        return np.where(t > self.t[-1], 0.0, held) if self.ended else held

    @property
    def end(self) -> float:
        """The last sample's time."""
        return float(self.t[-1])

    def breakpoints(self, t0, t1):
        return self.t[(self.t > t0) & (self.t < t1)]

    def exo(self):
        return Exo(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([1.0, 0.0]))

    def exo_state(self, t):
        # exo_states at one time, written for one: a third of its cost in the per-step loops that call it
        if self.ended and t >= self.t[-1]:  # right limits: over
            return np.zeros(2)
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        slope = self.slopes[i] if 0 <= i < len(self.slopes) else 0.0
        return np.array([float(self.value(t)), slope])

    def kernel_knots(self) -> tuple[np.ndarray, np.ndarray]:
        """(times, values) as the compiled kernels read them (ends held): an ended table's last sample doubled,
        its second copy zero (the kernels take the left limit at the first copy)."""
        if not self.ended:
            return self.t, self.v
        return np.append(self.t, self.t[-1]), np.append(self.v, 0.0)

    def exo_states(self, t: np.ndarray) -> np.ndarray:
        """exo_state at each of the times t, (len(t), 2)."""
        i = np.searchsorted(self.t, t, side="right") - 1
        held = np.append(self.slopes, 0.0)  # before the first sample and past the last the value is held
        states = np.stack([self.value(t), held[np.where((i >= 0) & (i < len(self.slopes)), i, -1)]], axis=1)
        if self.ended:  # right limits: over from the last sample on
            states[np.asarray(t) >= self.t[-1]] = 0.0
        return states


class ExpressionSignal(Signal):
    """A parsed expression in t; it jumps or kinks where an argument of sign, heaviside or abs crosses zero."""

    exact = False

    def __init__(self, text: str):
        from smdcli.expression import Expression

        self.expression = Expression(text)

    def value(self, t):
        return self.expression(t)

    def value_left(self, t):
        # an edge is the first float past the crossing (Expression.edges): the float before it is on the near side;
        # where that float is outside the expression's domain (sqrt(t) at t = 0) the value at t is the limit
        before = self.expression(np.nextafter(t, -np.inf))
        outside = ~np.isfinite(before)
        return np.where(outside, self.expression(t), before) if outside.any() else before

    def breakpoints(self, t0, t1):
        return self.expression.edges(t0, t1)

    def edge_count(self, t0, t1, limit=None):
        from smdcli.expression import TooManyEdges

        try:
            return len(self.expression.edges(t0, t1, limit))
        except TooManyEdges as exc:
            return exc.count


def build_signal(spec: ForceSpec) -> Signal:
    """The Signal a validated ForceSpec describes."""
    kind = spec.type
    if kind == "constant":
        return Constant(spec.amplitude)
    if kind == "step":
        return Step(spec.amplitude, spec.t0)
    if kind in ("sine", "cosine"):
        return Harmonic(spec.amplitude, spec.omega, spec.phase, cosine=(kind == "cosine"))
    if kind == "square":
        return Square(spec.amplitude, spec.omega, spec.duty, spec.t0)
    if kind == "fourier_square":
        return FourierSquare(spec.amplitude, spec.omega, spec.terms, spec.t0)
    if kind == "pulse":
        return Pulse(spec.amplitude, spec.t0, spec.duration)
    if kind == "chirp":
        return Chirp(spec.amplitude, spec.f0, spec.f1, spec.t1, spec.phase)
    if kind == "table":
        return Table(spec.t, spec.values, spec.interpolation)
    if kind == "expression":
        return ExpressionSignal(spec.expr)
    raise AssertionError(f"unvalidated force type {kind}")
