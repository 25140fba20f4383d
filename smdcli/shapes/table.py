"""`type = "table"`: samples held linearly or at the previous value (read from the scenario or a CSV file by
smdcli.scenario.forces, which owns files).
Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import numpy as np

from smdcli.shapes.base import Exo, Signal

TABLE_LINEAR, TABLE_PREVIOUS = 8, 9  # compiled row kinds


class Table(Signal):
    """Tabulated force: linear interpolation (first-order hold) or previous value; the first value held before the
    table, the last held after it, or, `ended`, zero after the last sample (a record that is over: its last sample
    is its value there, the jump to zero its right limit, as exo_state gives it)."""

    types = ("table",)
    fields = ("t", "values", "file", "interpolation", "format", "channel", "dt")
    kinds = (TABLE_LINEAR, TABLE_PREVIOUS)

    def __init__(self, times, values, interpolation: str, ended: bool = False):
        self.t = np.asarray(times, dtype=float)
        self.v = np.asarray(values, dtype=float)
        self.previous = interpolation == "previous"
        self.ended = ended
        slopes = np.diff(self.v) / np.diff(self.t) if len(self.t) > 1 else np.empty(0)
        self.slopes = np.zeros_like(slopes) if self.previous else slopes

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.t, spec.values, spec.interpolation)

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

    def as_record(self):
        return Table(self.t, self.v, "previous" if self.previous else "linear", ended=True)

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

    def exo_states(self, t: np.ndarray) -> np.ndarray:
        """exo_state at each of the times t, (len(t), 2)."""
        i = np.searchsorted(self.t, t, side="right") - 1
        held = np.append(self.slopes, 0.0)  # before the first sample and past the last the value is held
        states = np.stack([self.value(t), held[np.where((i >= 0) & (i < len(self.slopes)), i, -1)]], axis=1)
        if self.ended:  # right limits: over from the last sample on
            states[np.asarray(t) >= self.t[-1]] = 0.0
        return states

    def derivative(self, start):
        if self.previous or len(self.t) < 2:
            return None
        # The slope between knots, zero before the first and after the last (the ends are held).
        before = min(start, float(self.t[0])) - 1.0
        times = np.concatenate([[before], self.t])
        values = np.concatenate([[0.0], self.slopes, [0.0]])
        return Table(times, values, "previous")

    def kernel_knots(self) -> tuple[np.ndarray, np.ndarray]:
        """(times, values) as the compiled kernels read them (ends held): an ended table's last sample doubled,
        its second copy zero (the kernels take the left limit at the first copy)."""
        if not self.ended:
            return self.t, self.v
        return np.append(self.t, self.t[-1]), np.append(self.v, 0.0)

    def kernel_row(self):
        times, values = self.kernel_knots()
        return (TABLE_PREVIOUS if self.previous else TABLE_LINEAR), [], np.concatenate([times, values]), []
