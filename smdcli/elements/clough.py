"""The Clough spring: peak-oriented stiffness degradation (Clough and Johnston 1966), with Mahin and Bertero's
(1976) modification for partial reloading: reinforced-concrete members and the degrading storeys of collapse
studies.

    [[spring]]
    connects = ["ground", "m1"]
    law = "clough"
    k = 4000.0          # N/m, elastic (and unloading) stiffness
    fy = 150.0          # N, yield force
    hardening = 0.05    # b, -1 < b < 1: post-yield stiffness b k (negative: softening, P-Delta)

Loading starts on the bilinear backbone (k d up to fy, then fy + b k (|d| - fy/k)). Unloading runs with slope k;
once the force crosses zero, reloading runs on a straight line to the largest earlier excursion on that side (the
yield point where that side never yielded), then on the backbone. A reversal on an unloading line runs back along
it (elastic) and, at the point where that unloading began, goes on as it was. Mahin-Bertero: after a partial
reloading (a reversal on a reloading line), the next reloading on that side aims first at the point where that
last unloading began, then along the straight line from it to the largest excursion.

Every branch is a straight line T = s d + c, so the spring is linear between events and solved exactly event to
event. Stored (recoverable) energy is what an elastic unloading would give back, T^2 / (2k); the rest of the work
is hysteretic: the power T d' (1 - s/k). The Newmark family has no return mapping for it (use `exact`, `auto` or an
ODE method).

Must not import: scenario, model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from smdcli.elements.base import D, ON_SURFACE, RATE, Guard, KernelPiece, Law, Piece, State

ELASTIC, BACKBONE, UNLOAD, RELOAD = "elastic", "backbone", "unload", "reload"
MAX_WALK = 1000  # branches one jump of d may cross (a ground displacement's jump)


@dataclass(frozen=True)
class Clough(Law):
    """Peak-oriented degrading spring: elastic stiffness k [N/m], yield force fy [N], post-yield ratio b."""

    k: float
    fy: float
    hardening: float = 0.0

    table: ClassVar[str] = "spring"
    name: ClassVar[str] = "clough"
    keys: ClassVar[tuple[str, ...]] = ("k", "fy", "hardening")
    internal_names: ClassVar[tuple[str, ...]] = ("peak_positive", "peak_negative")
    units: ClassVar[dict[str, str]] = {"k": "N/m", "fy": "N", "hardening": "1"}
    affine_events: ClassVar[bool] = False  # a reloading line's slope is a quotient of its ends

    @classmethod
    def read(cls, t) -> "Clough":
        """From a [[spring]] table."""
        k, fy = t.number("k", positive=True), t.number("fy", positive=True)
        b = t.number("hardening", 0.0)
        if not -1.0 < b < 1.0:
            raise t.fail("hardening", f"expected a post-yield stiffness ratio b with -1 < b < 1, found {b:g}")
        return cls(k=k, fy=fy, hardening=b)

    # ----------------------------------------------------------------- the backbone and the lines

    @property
    def dy(self) -> float:
        """The yield deformation fy / k."""
        return self.fy / self.k

    def backbone(self, d: float) -> float:
        """The bilinear backbone's force at d."""
        if abs(d) <= self.dy:
            return self.k * d
        return math.copysign(self.fy + self.hardening * self.k * (abs(d) - self.dy), d)

    def _peak(self, internal: dict, side: float) -> tuple[float, float]:
        return (internal["dmax"], internal["fmax"]) if side > 0 else (internal["dmin"], internal["fmin"])

    def _line(self, state: State) -> tuple[float, float]:
        """(slope s, constant c) of the mode's branch: T = s d + c."""
        i = state.internal
        if state.mode == ELASTIC:
            return self.k, 0.0
        if state.mode == BACKBONE:
            side = i["side"]
            return self.hardening * self.k, side * self.fy * (1 - self.hardening)
        return i["slope"], i["af"] - i["slope"] * i["ad"]

    def _reload(self, internal: dict, side: float, anchor: tuple[float, float]) -> State:
        """Reloading toward `side` from the anchor: at its Mahin-Bertero point first where it has one ahead, then
        at its peak; where neither lies ahead (a drift past them), with slope k to the backbone."""
        ad, af = anchor
        target, leg = self._peak(internal, side), "peak"
        mb = internal.get(f"mb{'+' if side > 0 else '-'}")
        if mb is not None and side * (mb[0] - ad) > 0 and side * (target[0] - mb[0]) > 0:
            target, leg = mb, "mb"
        if not side * (target[0] - ad) > ON_SURFACE * self.dy:  # not ahead: slope k up to the backbone
            post = self.hardening * self.k
            d_meet = (side * self.fy * (1 - self.hardening) + self.k * ad - af) / (self.k - post)
            target, leg = (d_meet, self.backbone(d_meet)), "peak"
        slope = (target[1] - af) / (target[0] - ad)
        return State(RELOAD, {**internal, "side": side, "ad": ad, "af": af, "slope": slope, "td": target[0],
                              "tf": target[1], "leg": leg})

    def _unload(self, internal: dict, side: float, d: float, tension: float, partial: bool) -> State:
        """Unloading with slope k from (d, T), the side it came from `side`; `partial`: from a reloading line."""
        internal = dict(internal)
        if partial:  # Mahin-Bertero: the next reloading on this side aims here first
            internal[f"mb{'+' if side > 0 else '-'}"] = (d, tension)
        elif side * d >= side * self._peak(internal, side)[0]:  # from the backbone: the largest excursion so far
            internal.update({"dmax": d, "fmax": tension} if side > 0 else {"dmin": d, "fmin": tension})
            internal.pop(f"mb{'+' if side > 0 else '-'}", None)
        return State(UNLOAD, {**internal, "side": side, "ad": d, "af": tension, "slope": self.k,
                              "resume": "reload" if partial else "backbone", "back": False})

    # ----------------------------------------------------------------- the Law interface

    def start(self, d: float, rate: float) -> State:
        internal = {"dmax": self.dy, "fmax": self.fy, "dmin": -self.dy, "fmin": -self.fy, "side": 1.0}
        if abs(d) < self.dy:
            return State(ELASTIC, internal)
        side = 1.0 if d > 0 else -1.0  # deformed past yield at the start: it got there on the backbone
        state = State(BACKBONE, {**internal, "side": side})
        settled = self.settle(state, d, rate, lambda sign: sign * rate > 0)
        return settled[0] if settled else state

    def piece(self, state: State) -> Piece:
        s, c = self._line(state)
        i = state.internal
        side = i["side"]
        if state.mode == ELASTIC:
            guards = (Guard(D, self.dy, +1, "yield"), Guard(D, -self.dy, -1, "yield"))
        elif state.mode == BACKBONE:
            guards = (Guard(RATE, 0.0, -int(side), "unload"),)
        elif state.mode == UNLOAD and i.get("back"):  # running back up its unloading line, toward where it began
            guards = (Guard(D, i["ad"], int(side), "yield" if i["resume"] == "backbone" else "reload"),
                      Guard(RATE, 0.0, -int(side), "unload"))
        elif state.mode == UNLOAD:
            # its force crosses zero on the way down: reloading toward the other side; or it turns back (its guard
            # at where it began comes with the turn: set here, it would sit at its level from the first instant)
            guards = (Guard(D, i["ad"] - i["af"] / self.k, -int(side), "reload"),
                      Guard(RATE, 0.0, int(side), "unload"))
        else:
            reached = "yield" if i["leg"] == "peak" else "reload"
            guards = (Guard(D, i["td"], int(side), reached), Guard(RATE, 0.0, -int(side), "unload"))
        return Piece(stiffness=s, constant=c, guards=guards)

    def force_derivatives(self, state: State, d: float, rate: float) -> dict[str, float]:
        # elastic k d; the backbone b k d + side fy (1 - b); unloading and reloading lines are the state's (their
        # anchors, targets and slopes are internal variables, held)
        if state.mode == ELASTIC:
            return {"k": d, "fy": 0.0, "hardening": 0.0}
        if state.mode == BACKBONE:
            b, side = self.hardening, state.internal["side"]
            return {"k": b * d, "fy": side * (1 - b), "hardening": self.k * d - side * self.fy}
        return {"k": 0.0, "fy": 0.0, "hardening": 0.0}

    def event(self, state: State, kind: str, d: float, rate: float, tension: float) -> State:
        i = state.internal
        side = i["side"]
        T = self.tension(state, d, rate)
        if state.mode == ELASTIC:  # onto the backbone, the side it yields on
            return State(BACKBONE, {**i, "side": 1.0 if d > 0 else -1.0})
        if state.mode == BACKBONE:
            return self._unload(i, side, d, T, partial=False)
        if state.mode == RELOAD:
            if kind == "unload":
                return self._unload(i, side, d, T, partial=True)
            if i["leg"] == "mb":  # at the Mahin-Bertero point: on along the line from it to the peak
                peak = self._peak(i, side)
                slope = (peak[1] - i["tf"]) / (peak[0] - i["td"])
                return State(RELOAD, {**i, "ad": i["td"], "af": i["tf"], "slope": slope, "td": peak[0],
                                      "tf": peak[1], "leg": "peak"})
            return State(BACKBONE, dict(i))
        # unloading: it turns back (a reversal, "unload": elastic, up the same line) or down again; back where it
        # began it goes on as before; through zero force it reloads toward the other side
        if i.get("back"):
            if kind == "unload":
                return State(UNLOAD, {**i, "back": False})
            if i["resume"] == "backbone":
                return State(BACKBONE, {**i, "back": False})
            return self._reload({**i, "back": False}, side, (i["ad"], i["af"]))
        if kind == "unload":
            return State(UNLOAD, {**i, "back": True})
        zero = i["ad"] - i["af"] / self.k
        return self._reload(i, -side, (d, T) if side * i["af"] <= 0 else (zero, 0.0))

    def settle(self, state: State, d: float, rate: float, moving) -> tuple[State, str] | None:
        side = state.internal["side"]
        if state.mode == ELASTIC:
            if abs(self.k * d) >= self.fy * (1 - ON_SURFACE) and moving(1 if d > 0 else -1):
                return self.event(state, "yield", d, rate, 0.0), "yield"
            return None
        if state.mode in (BACKBONE, RELOAD) and not moving(side):
            return self.event(state, "unload", d, -side, 0.0), "unload"
        if state.mode == UNLOAD and side * state.internal["af"] <= 0 and moving(-side):
            return self.event(state, "reload", d, -side, 0.0), "reload"  # past zero force already: reloading
        return None

    def internal_values(self, state: State, d) -> tuple:
        return state.internal["dmax"] + 0.0 * d, state.internal["dmin"] + 0.0 * d

    def dissipation(self, state: State, d: float, rate: float, tension: float) -> tuple[str, float]:
        s, _ = self._line(state)
        return "hysteretic", tension * rate * (1 - s / self.k)

    @property
    def dissipation_never_decreases(self) -> bool:
        return self.hardening >= 0  # a softened backbone past zero force gives energy back

    def kernel_piece(self, state: State) -> KernelPiece:
        s, c = self._line(state)
        share = 1 - s / self.k
        return KernelPiece(term="hysteretic", pc=share * c, px=share * s) if share else KernelPiece()

    def stored(self, state: State, d: float) -> tuple[str, float]:
        T = self.tension(state, d, 0.0)
        return "strain", T * T / (2 * self.k)

    def jump(self, state: State, d_old: float, d_new: float) -> tuple[State, float]:
        """The straight path from d_old to d_new walked branch by branch, reversing first where it turns back;
        the hysteretic work on the way, the integral of (1 - s/k) T dd."""
        direction = 1.0 if d_new > d_old else -1.0
        settled = self.settle(state, d_old, direction, lambda sign: sign * direction > 0)
        state = settled[0] if settled else state
        if state.mode == UNLOAD and (direction == state.internal["side"]) != bool(state.internal.get("back")):
            state = State(UNLOAD, {**state.internal, "back": direction == state.internal["side"]})  # the turn
        d, work = d_old, 0.0
        for _ in range(MAX_WALK):
            s, c = self._line(state)
            ahead = [g for g in self.piece(state).guards if g.quantity == D and g.direction == direction
                     and direction * (g.level - d) > 0]
            guard = min(ahead, key=lambda g: direction * (g.level - d), default=None)
            end = d_new if guard is None or direction * (guard.level - d_new) >= 0 else guard.level
            work += (1 - s / self.k) * (0.5 * s * (end * end - d * d) + c * (end - d))
            d = end
            if d == d_new:
                return state, work
            state = self.event(state, guard.kind, d, direction, s * d + c)
        raise RuntimeError(f"a jump of d from {d_old:g} to {d_new:g} crossed more than {MAX_WALK} branches")

    def excess(self, d, rate, tension):
        """Its force never passes the backbone's reach: fy, plus b k |d| where it hardens."""
        import numpy as np

        bound = self.fy + max(self.hardening, 0.0) * self.k * np.abs(d)
        scale = self.fy + float(np.abs(self.k * d).max(initial=0.0))
        return np.abs(tension) - bound, scale, "its force stays within its hardening backbone's reach"
