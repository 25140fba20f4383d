"""Stops, gaps and impacts: a limit on an element's deformation d = x_b - x_a.

    [[stop]]
    connects = ["ground", "m1"]
    min = 0.0            # m: contact when d reaches min (omit: no lower limit)
    max = 0.02           # m: contact when d reaches max (omit: no upper limit)
    restitution = 0.8    # rigid impact: the relative velocity is reversed and scaled, 0 <= e <= 1
    # k = 1e6, c = 50.0  # compliant contact instead: a spring and a damper acting only while in contact

Rigid: at contact the relative velocity d' jumps to -e d', by an impulse along the element that conserves the
momentum of the masses involved (the energy lost is the impact term). With e = 0, or once a sequence of impacts
accumulates (a ball coming to rest: its flights followed until those left rise together less than the rounding
of the scene's length, then summed as the geometric series they are, and persistent contact), the stop holds d at its limit, its tension whatever keeps it there, until
that tension would pull (separation). Compliant: while d is past the limit, T = k (d - limit) + c d', the spring's
energy is the contact term and the damper's loss the impact term. Both are linear between events.

Must not import: scenario, model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from smdcli.elements.base import D, TENSION, Guard, KernelPiece, Law, Piece, State

FREE, AT_MIN, AT_MAX = "free", "contact-min", "contact-max"


@dataclass(frozen=True)
class Stop(Law):
    """Limits min and max [m] of d; a rigid stop's restitution e, or a compliant contact's k [N/m] and c [N s/m]."""

    min: float | None
    max: float | None
    restitution: float | None = None
    k: float | None = None
    c: float = 0.0

    table: ClassVar[str] = "stop"
    name: ClassVar[str] = "stop"
    keys: ClassVar[tuple[str, ...]] = ("min", "max", "restitution", "k", "c")
    units: ClassVar[dict[str, str]] = {"min": "m", "max": "m", "restitution": "1", "k": "N/m", "c": "N s/m"}

    @property
    def rebound(self) -> float:
        """The ratio of the rebound's speed to the approach's at a rigid impact (its coefficient e)."""
        return self.restitution

    @property
    def contact(self) -> str:
        """What its contact is, in a few characters: 'e = 0.8' or 'k = 1e+06 N/m'."""
        return f"e = {self.restitution:g}" if self.k is None else f"k = {self.k:g} N/m"

    def penalty(self, k: float, mass: float) -> "Stop":
        """The compliant contact that stands in for this rigid one: a spring k, damped so that a mass bouncing on it
        rebounds at this stop's e (e = exp(-zeta pi / sqrt(1 - zeta^2)))."""
        e = self.restitution
        zeta = 1.0 if e <= 0 else -math.log(e) / math.sqrt(math.pi**2 + math.log(e) ** 2)
        return Stop(self.min, self.max, k=k, c=2 * zeta * math.sqrt(k * mass))

    @classmethod
    def read(cls, t) -> "Stop":
        """From a [[stop]] table."""
        low, high = t.number("min", None), t.number("max", None)
        if low is None and high is None:
            raise t.fail("min", "expected min, max or both (the limits of d = x_b - x_a, in m)")
        if low is not None and high is not None and not low < high:
            raise t.fail("max", f"expected max > min, found min {low:g} and max {high:g}")
        compliant = t.has("k") or t.has("c")
        if compliant and t.has("restitution"):
            raise t.fail("restitution", "a stop is rigid (restitution) or compliant (k and c), not both")
        if compliant:
            return cls(low, high, k=t.number("k", positive=True), c=t.number("c", 0.0, minimum=0.0))
        e = t.number("restitution", 1.0)
        if not 0.0 <= e <= 1.0:
            raise t.fail("restitution", f"expected a coefficient of restitution 0 <= e <= 1, found {e:g}")
        return cls(low, high, restitution=e)

    @property
    def rigid(self) -> bool:
        """An impact and persistent contact (True), or a spring and damper while in contact (False)."""
        return self.k is None

    def start(self, d: float, rate: float) -> State:
        if self.min is not None and d <= self.min and (not self.rigid or d < self.min or rate <= 0):
            return State(AT_MIN)
        if self.max is not None and d >= self.max and (not self.rigid or d > self.max or rate >= 0):
            return State(AT_MAX)
        return State(FREE)

    def nearest(self, d: float) -> float:
        """The limit nearer to d: the one an impact or a contact at d is at."""
        return self.min if self.min is not None and (self.max is None or abs(d - self.min) <= abs(d - self.max)) \
            else self.max

    def limit(self, state: State) -> float:
        """The limit the state is in contact with."""
        return self.min if state.mode == AT_MIN else self.max

    def piece(self, state: State) -> Piece:
        if state.mode == FREE:
            guards = []
            if self.min is not None:
                guards.append(Guard(D, self.min, -1, "impact" if self.rigid else "contact"))
            if self.max is not None:
                guards.append(Guard(D, self.max, +1, "impact" if self.rigid else "contact"))
            return Piece(guards=tuple(guards))
        at_min = state.mode == AT_MIN
        if self.rigid:  # held at the limit; it separates where its force would pull (min) or push (max)
            return Piece(held=True, guards=(Guard(TENSION, 0.0, +1 if at_min else -1, "separation"),))
        limit = self.limit(state)
        return Piece(stiffness=self.k, damping=self.c, constant=-self.k * limit,
                     guards=(Guard(D, limit, +1 if at_min else -1, "separation"),))

    def force_derivatives(self, state: State, d: float, rate: float) -> dict[str, float] | None:
        given = {key: 0.0 for key in self.keys if getattr(self, key) is not None}
        if state.mode == FREE:
            return given
        if self.rigid:
            return None
        limit = "min" if state.mode == AT_MIN else "max"  # k (d - limit) + c d'
        return {**given, "k": d - getattr(self, limit), "c": rate, limit: -self.k}

    def event(self, state: State, kind: str, d: float, rate: float, tension: float) -> State:
        if kind == "separation":
            return State(FREE)
        if kind in ("contact", "rest"):
            return State(AT_MIN if self.nearest(d) == self.min else AT_MAX)
        return State(FREE)  # an impact with e > 0: free again, moving away

    def start_excess(self, d: float):
        """A rigid stop cannot start passed."""
        import numpy as np

        return self.excess(np.array([d]), np.zeros(1), np.zeros(1))

    def excess(self, d, rate, tension):
        """A rigid stop is never passed: d within [min, max] (a compliant one is, by its penetration)."""
        import numpy as np

        if not self.rigid:
            return None
        over = np.full(np.shape(d), -np.inf)
        if self.max is not None:
            over = np.maximum(over, d - self.max)
        if self.min is not None:
            over = np.maximum(over, self.min - d)
        limits = [abs(v) for v in (self.min, self.max) if v is not None]
        return over, max(max(limits), float(np.max(np.abs(d), initial=0.0))), "a rigid stop is never passed"

    def dissipation(self, state: State, d: float, rate: float, tension: float) -> tuple[str, float]:
        if state.mode == FREE or self.rigid:
            return "", 0.0
        return "impact", self.c * rate * rate

    def kernel_piece(self, state: State) -> KernelPiece:
        if state.mode == FREE or self.rigid:
            return KernelPiece()
        return KernelPiece(term="impact", pd=self.c)

    def stored(self, state: State, d: float) -> tuple[str, float]:
        if state.mode == FREE or self.rigid:
            return "contact", 0.0
        gap = d - self.limit(state)
        return "contact", 0.5 * self.k * gap * gap
