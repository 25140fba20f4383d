"""What every force shape answers: its scenario fields, its value and edges, its exact generator, its derivative
and its compiled row.

A force shape (constant, step, sine, pulse, table...) is one class in its own module here, registered in
registry.py; nothing outside this package and the compiled kernel that evaluates its row (smdcli.kernels.forces)
names one. A shape is *exactly integrable* when, between its breakpoints, it is the output g.w(t) of a small
linear system w' = S w (an "exosystem"): the exact solver augments the structure's state with w and propagates
both with one matrix exponential, reseeding w from `exo_state` at every breakpoint. A shape without such a form
(a frequency sweep, a formula) returns None from `exo` and is sampled there.

Imports nothing of smd but the expression parser (the bottom layer): the scenario reader, the model, the kernels
and the solvers consult it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Sequence

import numpy as np

# Phase tolerance (in periods) within which a time counts as on a periodic shape's edge; breakpoints computed as
# t0 + k*T land within rounding of it. The compiled kernels use the same.
EDGE_SNAP = 1e-9


@dataclass(frozen=True)
class Exo:
    """Exosystem form: u(t) = g . w(t), w' = S w between breakpoints."""

    S: np.ndarray
    g: np.ndarray


class Signal:
    """A scalar force signal u(t) [N] and the force shape it is read as."""

    types: ClassVar[tuple[str, ...]] = ()  # the scenario's `type` names this class reads
    fields: ClassVar[tuple[str, ...]] = ()  # the keys it takes beyond on and type
    kinds: ClassVar[tuple[int, ...]] = ()  # its compiled row kinds (smdcli.kernels.forces), unique to it
    exact: ClassVar[bool] = True  # has an exosystem form: the exact solver integrates it exactly
    series: ClassVar[bool] = True  # the Taylor solver has its series (smdcli.kernels.forces.force_series)
    shock: ClassVar[bool] = False  # one event, whose velocity change as a ground acceleration is meant (delta-v)
    schema: ClassVar[dict[str, Any]] = {}  # JSON Schema of its keys that are not plain numbers
    scaled_by_amplitude: ClassVar[bool] = False  # its `amplitude` attribute multiplies the whole signal, nothing else

    @classmethod
    def read(cls, t) -> dict[str, Any]:
        """Its fields from a scenario table `t` (smdcli.scenario.reader's), checked, as ForceSpec's keywords."""
        raise NotImplementedError

    @classmethod
    def from_spec(cls, spec) -> Signal:
        """The signal a validated ForceSpec of this type describes."""
        raise NotImplementedError

    @classmethod
    def resolution_problem(cls, spec, start: float, end: float, step: float) -> tuple[str, str] | None:
        """(field, why) where the force changes faster than the output grid's `step` can hold over [start, end]."""
        return None

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

    def phase_origin(self) -> float:
        """Where the generator's state holds still as its frequency moves (the origin of its phase): 0, or the time a
        shape's series counts from."""
        return 0.0

    def derivative(self, start: float) -> Signal | None:
        """d/dt between the signal's jumps, for a run from `start` (None where it is zero); the jumps themselves
        are the caller's (value - value_left at the breakpoints)."""
        raise NotImplementedError

    def ratio_to(self, other: Signal) -> float | None:
        """c where this signal is c times `other` at every time (the same shape with another amplitude), else None."""
        if type(other) is not type(self) or not self.scaled_by_amplitude or other.amplitude == 0:
            return None
        mine, theirs = dict(vars(self)), dict(vars(other))
        ratio = mine.pop("amplitude") / theirs.pop("amplitude")
        return ratio if mine == theirs else None

    def harmonic_terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(w, c, p) with the signal = sum c sin(w t + p), or None for a signal that is not a sum of harmonics."""
        return None

    @property
    def period(self) -> float | None:
        """The period of a periodic signal, None for the rest."""
        return None

    def as_record(self) -> Signal:
        """The signal as a record that is over at its last sample (a recorded ground acceleration); itself for a
        shape that has no last sample."""
        return self

    def kernel_row(self) -> tuple[int, list[float], Sequence[float], list[int]]:
        """(kind, parameters, packed data (a list or an array), expression opcodes): the row smdcli.kernels.forces
        evaluates."""
        raise NotImplementedError


def read_omega(t, allow_period: bool) -> float:
    """An angular frequency given as exactly one of omega [rad/s], frequency [Hz] or (if allowed) period [s]."""
    keys = ("omega", "frequency") + (("period",) if allow_period else ())
    given = [k for k in keys if t.has(k)]
    if len(given) != 1:
        want = " or ".join(keys)
        if not given:
            raise t.fail(keys[0], f"required field is missing (expected exactly one of {want})")
        raise t.fail(given[1], f"give exactly one of {want}, found {' and '.join(given)}")
    key = given[0]
    value = t.number(key, positive=(key != "omega"), minimum=0.0)
    omega = value if key == "omega" else 2 * math.pi * value if key == "frequency" else 2 * math.pi / value
    if not math.isfinite(omega):  # 2 pi f past 1.8e308, or a period below 3.5e-308
        raise t.fail(key, f"expected an angular frequency below 1.8e308 rad/s, found {key} = {value:g} "
                          f"({'2 pi f' if key == 'frequency' else '2 pi / period'} overflows)")
    return omega
