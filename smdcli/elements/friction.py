"""Friction between two masses, or a mass and the ground (which may move, or be a belt), with true stick and slip.

    [[friction]]
    connects = ["ground", "m1"]
    force = 2.0                 # N, kinetic (Coulomb) friction force, > 0
    static = 2.5                # N, breakaway force >= force (default: force)
    # stribeck_velocity = 0.01  # m/s: while slipping the force falls from static to force as exp(-(v/vs)^2)
    # viscous = 0.5             # N s/m, a viscous part while slipping
    # regularization = 1e-4     # m/s: a smooth force tanh(v / v_r) instead of stick and slip, for comparison
    # belt_velocity = 0.1       # m/s, contacts with the ground only: the surface moves at this speed

The relative velocity is v = d' (less the belt's speed where the ground end is a belt). Slipping (v != 0), the
tension opposes the sliding: T = sign(v) (F + (Fs - F) exp(-(v/vs)^2)) + c v. Stuck, v stays exactly zero and the
tension is whatever holds it there (the constraint's force, solved for with every other stuck contact at once);
it slips when that would pass Fs. A slipping contact whose velocity reaches zero sticks if the force that
holds it is at most Fs, else slides on the other way. Coulomb friction (no Stribeck, no regularization) is
linear in each mode: scenes of it are solved exactly, event to event.

Must not import: scenario, model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from smdcli.elements.base import RATE, TENSION, Guard, KernelPiece, Law, Piece, State

STICK, PLUS, MINUS, SMOOTH = "stick", "slip+", "slip-", "smooth"
SMOOTH_STRIBECK, SMOOTH_TANH = 2, 3  # its smooth tensions' kernel codes (smdcli.kernels.rhs)


@dataclass(frozen=True)
class Friction(Law):
    """Kinetic force F [N], breakaway Fs [N], Stribeck velocity [m/s], viscous c [N s/m], regularization [m/s],
    belt velocity [m/s]."""

    force: float
    static: float
    stribeck_velocity: float | None = None
    viscous: float = 0.0
    regularization: float | None = None
    belt_velocity: float = 0.0

    table: ClassVar[str] = "friction"
    name: ClassVar[str] = "coulomb"
    holds_impulse: ClassVar[bool] = False  # its force is bounded: no impulse through it, stuck or not
    keys: ClassVar[tuple[str, ...]] = ("force", "static", "stribeck_velocity", "viscous", "regularization",
                                       "belt_velocity")
    units: ClassVar[dict[str, str]] = {"force": "N", "static": "N", "stribeck_velocity": "m/s", "viscous": "N s/m",
                                       "regularization": "m/s", "belt_velocity": "m/s"}

    @property
    def stiff(self) -> bool:
        """A regularized (tanh) law is stiff near zero speed."""
        return self.regularization is not None

    @classmethod
    def read(cls, t) -> "Friction":
        """From a [[friction]] table."""
        force = t.number("force", positive=True)
        static = t.number("static", force)
        if static < force:
            raise t.fail("static", f"expected a breakaway force >= the kinetic force {force:g} N, found {static:g}")
        stribeck = t.number("stribeck_velocity", None, positive=True)
        regularization = t.number("regularization", None, positive=True)
        if stribeck is not None and regularization is not None:
            raise t.fail("regularization", "a regularized law has no stick and so no Stribeck curve; give one of "
                                           "stribeck_velocity and regularization")
        if regularization is not None and static != force:
            raise t.fail("static", "a regularized law has no stick, so no breakaway force; drop static or "
                                   "regularization")
        return cls(force=force, static=static, stribeck_velocity=stribeck, viscous=t.number("viscous", 0.0, minimum=0.0),
                   regularization=regularization, belt_velocity=t.number("belt_velocity", 0.0))

    @property
    def piecewise_linear(self) -> bool:  # type: ignore[override]
        """Coulomb (with a viscous part) is linear in each mode; Stribeck and tanh are not."""
        return self.stribeck_velocity is None and self.regularization is None

    @property
    def law_name(self) -> str:
        """coulomb, stribeck or regularized: what a message calls it."""
        return "regularized" if self.regularization else "stribeck" if self.stribeck_velocity else "coulomb"

    @property
    def capacity(self) -> float:  # type: ignore[override]
        """Stuck, it holds at most its breakaway force: contacts stuck on one row share a load in proportion."""
        return self.static

    def slip_force(self, speed: float) -> float:
        """The friction force's size while slipping at |v| = speed (the viscous part aside)."""
        if self.stribeck_velocity is None:
            return self.force
        return self.force + (self.static - self.force) * math.exp(-(speed / self.stribeck_velocity) ** 2)

    def start(self, d: float, rate: float) -> State:
        if self.regularization is not None:
            return State(SMOOTH)
        if rate > 0:
            return State(PLUS)
        if rate < 0:
            return State(MINUS)
        return State(STICK)

    def piece(self, state: State) -> Piece:
        if state.mode == SMOOTH:
            reg, force = self.regularization, self.force
            return Piece(damping=self.viscous, nonlinear=lambda d, rate, internal: force * math.tanh(rate / reg))
        if state.mode == STICK:
            return Piece(held=True, guards=(Guard(TENSION, self.static, +1, "slip"),
                                            Guard(TENSION, -self.static, -1, "slip")))
        sign = 1.0 if state.mode == PLUS else -1.0
        guard = (Guard(RATE, 0.0, -int(sign), "stick"),)
        if self.stribeck_velocity is None:
            return Piece(damping=self.viscous, constant=sign * self.force, guards=guard)
        return Piece(damping=self.viscous, guards=guard,
                     nonlinear=lambda d, rate, internal: sign * self.slip_force(abs(rate)))

    def force_derivatives(self, state: State, d: float, rate: float) -> dict[str, float] | None:
        if state.mode == STICK:
            return None
        # the viscous part c d', then the law's: force tanh(d'/r), sign F, or sign (F + (Fs - F) e) with e the Stribeck
        # factor; d' = (the masses' rate) + belt speed, so d/d(belt) is d/d(d')
        out = {"force": 0.0, "static": 0.0, "viscous": rate, "belt_velocity": self.viscous}
        if state.mode == SMOOTH:
            x = rate / self.regularization
            sech2 = _sech2(x)
            out.update(force=math.tanh(x), regularization=-self.force * sech2 * x / self.regularization)
            out["belt_velocity"] += self.force * sech2 / self.regularization
            return out
        sign = 1.0 if state.mode == PLUS else -1.0
        if self.stribeck_velocity is None:
            out["force"] = sign
            return out
        vs, ratio = self.stribeck_velocity, rate / self.stribeck_velocity
        e = math.exp(-ratio**2)
        out.update(force=sign * (1 - e), static=sign * e,
                   stribeck_velocity=sign * (self.static - self.force) * e * 2 * ratio**2 / vs)
        out["belt_velocity"] += sign * (self.static - self.force) * e * (-2 * ratio / vs)
        return out

    def key_scale(self, key: str) -> float | None:
        # the force turns over the slip's regularization (tanh) or Stribeck velocity: so does it in the belt's speed
        # (stepped in its own 0.2 m/s over r = 1e-3 m/s, a five-point stencil was 1.1e-3 off the complex step)
        return (self.regularization or self.stribeck_velocity) if key == "belt_velocity" else None

    def smooth_jacobian(self, state: State, d: float, rate: float):
        # regularized: T = F tanh(d'/r) (c d' is in the piece's damping) has no internal state; stick and slip have
        # none to give (Coulomb's sensitivities are event to event, Stribeck's not built)
        if state.mode != SMOOTH:
            return None
        return (0.0, self.force * _sech2(rate / self.regularization) / self.regularization), ()

    def event(self, state: State, kind: str, d: float, rate: float, tension: float) -> State:
        if kind == "slip":
            return State(PLUS if tension > 0 else MINUS)
        return State(STICK)  # "stick": a candidate; the scene's resolution decides (see solvers.decisions)

    def excess(self, d, rate, tension):
        """Its force never passes its breakaway (or, regularized, its kinetic force), less the viscous part."""
        import numpy as np

        bound = self.force if self.regularization is not None else self.static
        return (np.abs(tension) - self.viscous * np.abs(rate) - bound, bound,
                f"its force stays within {'the kinetic' if self.regularization else 'its static'} force "
                f"{bound:g} N")

    def dissipation(self, state: State, d: float, rate: float, tension: float) -> tuple[str, float]:
        return "friction", (tension * rate if state.mode != STICK else 0.0)

    def kernel_piece(self, state: State) -> KernelPiece:
        if state.mode == STICK:
            return KernelPiece()
        if state.mode == SMOOTH:
            return KernelPiece(SMOOTH_TANH, (self.force, self.regularization), "friction", self.viscous)
        sign = 1.0 if state.mode == PLUS else -1.0
        if self.stribeck_velocity is None:
            return KernelPiece(term="friction", pd=self.viscous, pc=sign * self.force)
        return KernelPiece(SMOOTH_STRIBECK, (sign, self.force, self.static, self.stribeck_velocity), "friction",
                           self.viscous)


def _sech2(x: float) -> float:
    """sech(x)^2, 0 where cosh overflows (|x| past 350: below the smallest double anyway)."""
    return 1.0 / math.cosh(x) ** 2 if abs(x) < 350 else 0.0
