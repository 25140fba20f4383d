"""Elastic-perfectly-plastic and bilinear (kinematic hardening) springs: OpenSees' ElasticPP and Steel01-like
Hardening without isotropic hardening.

    [[spring]]
    connects = ["ground", "m1"]
    law = "elastoplastic"   # k (N/m), fy (N): |T| <= fy, the plastic deformation d_p absorbs the rest
    k = 4000.0
    fy = 150.0
    # law = "bilinear", hardening = b (-1 < b < 1): an elastic b k in parallel with an elastoplastic (1-b) k
    #   yielding at (1-b) fy, so the first yield is at fy and the post-yield stiffness b k (negative: softening,
    #   as P-Delta makes a storey's)

Modes: elastic (T = k (d - d_p)), plastic+ (T = fy, d_p = d - fy/k follows d), plastic- (T = -fy). Yield where
the elastic tension reaches +-fy; unloading where d' turns back (then elastic with d_p frozen). The plastic work
fy |d d_p| is the hysteretic energy. The return mapping of a step (return_map) is what the Newmark family uses,
with its consistent tangent (k elastic, 0 plastic).

Must not import: scenario, model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from typing import ClassVar

from smdcli.elements.base import D, NEWMARK_CORE, ON_SURFACE, RATE, Guard, KernelPiece, Law, Piece, State

ELASTIC, PLUS, MINUS = "elastic", "plastic+", "plastic-"


@dataclass(frozen=True)
class Elastoplastic(Law):
    """Elastic-perfectly-plastic: stiffness k [N/m] up to the yield force fy [N]."""

    k: float
    fy: float

    table: ClassVar[str] = "spring"
    name: ClassVar[str] = "elastoplastic"
    keys: ClassVar[tuple[str, ...]] = ("k", "fy")
    internal_names: ClassVar[tuple[str, ...]] = ("plastic_deformation",)
    units: ClassVar[dict[str, str]] = {"k": "N/m", "fy": "N", "hardening": "1"}

    @classmethod
    def read(cls, t) -> "Elastoplastic":
        """From a [[spring]] table (t: the scenario reader's table)."""
        return cls(k=t.number("k", positive=True), fy=t.number("fy", positive=True))

    @property
    def core(self) -> "Elastoplastic":
        """The elastoplastic part (itself)."""
        return self

    def start(self, d: float, rate: float) -> State:
        """Deformed past its yield at the start (an initial displacement beyond fy / k), it yielded on the way there:
        it starts on its yield surface with that plastic deformation, never holding more than its yield force."""
        core = self.core
        trial = core.k * d
        dp = d - math.copysign(core.fy / core.k, trial) if abs(trial) > core.fy else 0.0
        state = State(ELASTIC, {"dp": dp, "work": 0.0})
        return self._settle(state, d, rate)

    def _settle(self, state: State, d: float, rate: float) -> State:
        """At the yield surface, loading outward: plastic; else elastic (the mode a point on the surface takes)."""
        core = self.core
        trial = core.k * (d - state.internal["dp"])
        if trial >= core.fy and rate > 0:
            return State(PLUS, {**state.internal, "dp": d - core.fy / core.k})
        if trial <= -core.fy and rate < 0:
            return State(MINUS, {**state.internal, "dp": d + core.fy / core.k})
        return State(ELASTIC, dict(state.internal))

    def piece(self, state: State) -> Piece:
        core = self.core
        if state.mode == ELASTIC:
            dp = state.internal["dp"]
            return Piece(stiffness=core.k, constant=-core.k * dp,
                         guards=(Guard(D, dp + core.fy / core.k, +1, "yield"),
                                 Guard(D, dp - core.fy / core.k, -1, "yield")))
        sign = 1.0 if state.mode == PLUS else -1.0
        return Piece(constant=sign * core.fy, guards=(Guard(RATE, 0.0, -int(sign), "unload"),))

    def force_derivatives(self, state: State, d: float, rate: float) -> dict[str, float]:
        elastic = d - state.internal["dp"] if state.mode == ELASTIC else 0.0  # the core's force: k elastic + fy sign
        return self._chained(elastic, {PLUS: 1.0, MINUS: -1.0}.get(state.mode, 0.0), d)

    def _chained(self, by_k: float, by_fy: float, d: float) -> dict[str, float]:
        """The parameters' derivatives from the core's force's: by its stiffness and by its yield force."""
        return {"k": by_k, "fy": by_fy}

    def event(self, state: State, kind: str, d: float, rate: float, tension: float) -> State:
        core = self.core
        if kind == "yield":
            plus = d >= state.internal["dp"]
            return State(PLUS if plus else MINUS, dict(state.internal))
        # unload: elastic again, the plastic deformation where yielding left it
        sign = 1.0 if state.mode == PLUS else -1.0
        return State(ELASTIC, {**state.internal, "dp": d - sign * core.fy / core.k})

    def settle(self, state: State, d: float, rate: float, moving) -> tuple[State, str] | None:
        core = self.core
        if state.mode == ELASTIC:
            trial = core.k * (d - state.internal["dp"])
            if abs(trial) < core.fy * (1 - ON_SURFACE):
                return None
            side = 1 if trial > 0 else -1
            return (self.event(state, "yield", d, rate, 0.0), "yield") if moving(side) else None
        sign = 1.0 if state.mode == PLUS else -1.0
        return None if moving(sign) else (self.event(state, "unload", d, rate, 0.0), "unload")

    def newmark_rows(self, d: float) -> list[tuple[int, tuple[float, ...], float]]:
        """Its elastic-perfectly-plastic core, from the plastic deformation it starts with (on its surface where d
        is past yield)."""
        return [(NEWMARK_CORE, (self.core.k, self.core.fy), self.start(d, 0.0).internal["dp"])]

    def plastic_deformation(self, state: State, d: float) -> float:
        """d_p at deformation d: frozen while elastic, following d while yielding."""
        core = self.core
        if state.mode == ELASTIC:
            return state.internal["dp"]
        return d - (core.fy if state.mode == PLUS else -core.fy) / core.k

    def internal_values(self, state: State, d: float) -> tuple[float, ...]:
        return (self.plastic_deformation(state, d),)

    def excess(self, d, rate, tension):
        """Its force, less the linear part b k d of a bilinear spring, never passes the yield force of its core."""
        import numpy as np

        core = self.core
        linear = self.linear_stiffness * d  # its rounding is the difference's: a softening spring's runs far
        return (np.abs(tension - linear) - core.fy, core.fy + float(np.abs(linear).max(initial=0.0)),
                f"its yield surface (|T - b k d| <= {core.fy:g} N) is never passed")

    def dissipation(self, state: State, d: float, rate: float, tension: float) -> tuple[str, float]:
        core = self.core
        return "hysteretic", (core.fy * abs(rate) if state.mode != ELASTIC else 0.0)

    def kernel_piece(self, state: State) -> KernelPiece:
        if state.mode == ELASTIC:
            return KernelPiece()
        return KernelPiece(term="hysteretic", pc=(self.core.fy if state.mode == PLUS else -self.core.fy))

    def stored(self, state: State, d: float) -> tuple[str, float]:
        core = self.core
        elastic = d - self.plastic_deformation(state, d)
        return "strain", 0.5 * core.k * elastic * elastic

    def jump(self, state: State, d_old: float, d_new: float) -> tuple[State, float]:
        # the straight path from d_old to d_new return-mapped: the core yields on the way where the trial force
        # passes fy, dissipating fy |change of d_p|; the mode is then decided by the motion (solvers.decisions)
        dp = self.plastic_deformation(state, d_old)
        _, _, dp_new = self.return_map(d_new, dp)
        return State(ELASTIC, {**state.internal, "dp": dp_new}), self.core.fy * abs(dp_new - dp)

    def return_map(self, d: float, dp: float) -> tuple[float, float, float]:
        """(tension, tangent, d_p) of a trial deformation d from the committed d_p: a step's return mapping."""
        core = self.core
        trial = core.k * (d - dp)
        if abs(trial) <= core.fy:
            return trial, core.k, dp
        sign = 1.0 if trial > 0 else -1.0
        return sign * core.fy, 0.0, d - sign * core.fy / core.k


@dataclass(frozen=True)
class Bilinear(Elastoplastic):
    """Bilinear with kinematic hardening: initial stiffness k, yield fy, post-yield stiffness b k."""

    hardening: float = 0.0

    name: ClassVar[str] = "bilinear"
    keys: ClassVar[tuple[str, ...]] = ("k", "fy", "hardening")

    @classmethod
    def read(cls, t) -> "Bilinear":
        k, fy = t.number("k", positive=True), t.number("fy", positive=True)
        b = t.number("hardening")
        if not -1.0 < b < 1.0:
            raise t.fail("hardening", f"expected a post-yield stiffness ratio b with -1 < b < 1, found {b:g}")
        return cls(k=k, fy=fy, hardening=b)

    @property
    def core(self) -> Elastoplastic:
        """The elastoplastic part: stiffness (1 - b) k, yield (1 - b) fy."""
        return Elastoplastic((1 - self.hardening) * self.k, (1 - self.hardening) * self.fy)

    @property
    def linear_stiffness(self) -> float:
        return self.hardening * self.k

    def _chained(self, by_k: float, by_fy: float, d: float) -> dict[str, float]:
        # b k d + (1 - b) k by_k + (1 - b) fy by_fy
        b = self.hardening
        return {"k": b * d + (1 - b) * by_k, "fy": (1 - b) * by_fy,
                "hardening": self.k * d - self.k * by_k - self.fy * by_fy}
