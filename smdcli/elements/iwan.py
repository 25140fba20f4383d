"""The Iwan (Masing, multilinear) spring: N elastic-perfectly-plastic elements in parallel, the distributed-yield
model of bolted joints and soils (Iwan 1966).

    [[spring]]
    connects = ["ground", "m1"]
    law = "iwan"
    k = [3000.0, 2000.0, 1000.0]   # N/m, each element's stiffness
    fy = [20.0, 40.0, 60.0]        # N, each element's yield force

Its backbone is multilinear (the stiffness drops by k_i as element i yields, at d = fy_i / k_i from rest), and it
unloads and reloads by Masing's rule (the backbone doubled) because each element remembers its own plastic
deformation d_p,i. In a mode each element is elastic (T_i = k_i (d - d_p,i)) or yielding (T_i = +-fy_i): the
spring is linear between events, solved exactly event to event. An element yields where its elastic tension
reaches its yield force; every yielding element unloads where d' turns back. It is N `elastoplastic` springs in
one table, and equals them to rounding (tests/test_iwan.py); the Newmark family steps each element by its
return mapping.

Must not import: scenario, model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from smdcli.elements.base import D, NEWMARK_CORE, ON_SURFACE, RATE, Guard, KernelPiece, Law, Piece, State
from smdcli.elements.elastoplastic import Elastoplastic

ELASTIC, PLUS, MINUS = "e", "+", "-"  # each element's mode, one character each in State.mode
MAX_ELEMENTS = 100
SAME_LEVEL = 1e-9  # of an element's yield force: elements this near their surfaces at a yield event yield together


@dataclass(frozen=True)
class Iwan(Law):
    """N elastic-perfectly-plastic elements in parallel: stiffnesses k [N/m] and yield forces fy [N]."""

    k: tuple[float, ...]
    fy: tuple[float, ...]

    table: ClassVar[str] = "spring"
    name: ClassVar[str] = "iwan"
    keys: ClassVar[tuple[str, ...]] = ("k", "fy")
    arrays: ClassVar[tuple[str, ...]] = ("k", "fy")  # keys given as arrays, one value per element
    units: ClassVar[dict[str, str]] = {"k": "N/m", "fy": "N"}

    @classmethod
    def read(cls, t) -> "Iwan":
        """From a [[spring]] table: k and fy, arrays of one positive number per element."""
        k, fy = t.numbers("k"), t.numbers("fy")
        if not 1 <= len(k) <= MAX_ELEMENTS:
            raise t.fail("k", f"expected 1 to {MAX_ELEMENTS} stiffnesses, one per element, found {len(k)}")
        if len(fy) != len(k):
            raise t.fail("fy", f"expected {len(k)} yield forces (one per entry of k), found {len(fy)}")
        for key, values in (("k", k), ("fy", fy)):
            for i, value in enumerate(values):
                if not value > 0:
                    raise t.fail(f"{key}[{i}]", f"expected a positive number, found {value:g}")
        return cls(k=tuple(k), fy=tuple(fy))

    @property
    def parts(self) -> tuple[Elastoplastic, ...]:
        """Its elements, each an elastoplastic spring (their start and return mapping are theirs)."""
        return tuple(Elastoplastic(k, fy) for k, fy in zip(self.k, self.fy))

    @property
    def elastic_stiffness(self) -> float:
        return float(sum(self.k))

    @property
    def internal_names(self) -> tuple[str, ...]:
        return tuple(f"plastic_deformation_{i + 1}" for i in range(len(self.k)))

    def _dp(self, state: State, i: int, d: float) -> float:
        """Element i's plastic deformation at d: frozen while elastic, following d while yielding."""
        mode = state.mode[i]
        if mode == ELASTIC:
            return state.internal[f"dp{i}"]
        return d - (self.fy[i] if mode == PLUS else -self.fy[i]) / self.k[i]

    def start(self, d: float, rate: float) -> State:
        """Each element deformed past its yield at the start yielded on the way there: it starts on its surface."""
        internal = {"work": 0.0}
        for i, part in enumerate(self.parts):
            internal[f"dp{i}"] = part.start(d, 0.0).internal["dp"]
        state = State(ELASTIC * len(self.k), internal)
        settled = self.settle(state, d, rate, lambda sign: sign * rate > 0)
        return settled[0] if settled else state

    def settle(self, state: State, d: float, rate: float, moving) -> tuple[State, str] | None:
        """An elastic element on its surface, loading outward, yields; a yielding one no longer loading unloads."""
        modes, internal, kind = list(state.mode), dict(state.internal), None
        for i, (k, fy) in enumerate(zip(self.k, self.fy)):
            if modes[i] == ELASTIC:
                trial = k * (d - internal[f"dp{i}"])
                side = 0 if abs(trial) < fy * (1 - ON_SURFACE) else (1 if trial > 0 else -1)
                if side and moving(side):
                    modes[i], kind = PLUS if side > 0 else MINUS, "yield"
            else:
                sign = 1.0 if modes[i] == PLUS else -1.0
                if not moving(sign):
                    internal[f"dp{i}"] = d - sign * fy / k
                    modes[i], kind = ELASTIC, kind or "unload"
        return (State("".join(modes), internal), kind) if kind else None

    def piece(self, state: State) -> Piece:
        stiffness = constant = 0.0
        guards = []
        for i, (k, fy) in enumerate(zip(self.k, self.fy)):
            mode = state.mode[i]
            if mode == ELASTIC:
                dp = state.internal[f"dp{i}"]
                stiffness += k
                constant -= k * dp
                guards += [Guard(D, dp + fy / k, +1, "yield"), Guard(D, dp - fy / k, -1, "yield")]
            else:
                constant += fy if mode == PLUS else -fy
        for mode, direction in ((PLUS, -1), (MINUS, +1)):
            if mode in state.mode:
                guards.append(Guard(RATE, 0.0, direction, "unload"))
        return Piece(stiffness=stiffness, constant=constant, guards=tuple(guards))

    def force_derivatives(self, state: State, d: float, rate: float) -> dict[str, float]:
        out = {}
        for i, mode in enumerate(state.mode):  # each part: k_i (d - dp_i) elastic, +-fy_i plastic
            out[f"k[{i}]"] = d - state.internal[f"dp{i}"] if mode == ELASTIC else 0.0
            out[f"fy[{i}]"] = 0.0 if mode == ELASTIC else (1.0 if mode == PLUS else -1.0)
        return out

    def event(self, state: State, kind: str, d: float, rate: float, tension: float) -> State:
        modes, internal = list(state.mode), dict(state.internal)
        if kind == "yield":  # the elastic elements whose surface d has reached (the nearest, and any within rounding)
            gaps = {}
            for i, (k, fy) in enumerate(zip(self.k, self.fy)):
                if modes[i] == ELASTIC:
                    gaps[i] = (abs(k * (d - internal[f"dp{i}"])) - fy) / fy
            nearest = max(gaps.values())
            for i, gap in gaps.items():
                if gap >= min(nearest, 0.0) - SAME_LEVEL:
                    modes[i] = PLUS if d >= internal[f"dp{i}"] else MINUS
            return State("".join(modes), internal)
        for i, (k, fy) in enumerate(zip(self.k, self.fy)):  # unload: every yielding element, d_p where it stopped
            if modes[i] != ELASTIC:
                internal[f"dp{i}"] = d - (fy if modes[i] == PLUS else -fy) / k
                modes[i] = ELASTIC
        return State("".join(modes), internal)

    def internal_values(self, state: State, d) -> tuple:
        return tuple(self._dp(state, i, d) for i in range(len(self.k)))

    def excess(self, d, rate, tension):
        """Its force never passes the sum of its elements' yield forces."""
        import numpy as np

        total = float(sum(self.fy))
        return np.abs(tension) - total, total, f"its force stays within the sum of its yield forces ({total:g} N)"

    def dissipation(self, state: State, d: float, rate: float, tension: float) -> tuple[str, float]:
        return "hysteretic", sum(fy for fy, mode in zip(self.fy, state.mode) if mode != ELASTIC) * abs(rate)

    def kernel_piece(self, state: State) -> KernelPiece:
        pc = sum(fy if mode == PLUS else -fy for fy, mode in zip(self.fy, state.mode) if mode != ELASTIC)
        return KernelPiece(term="hysteretic", pc=pc) if state.mode.strip(ELASTIC) else KernelPiece()

    def stored(self, state: State, d: float) -> tuple[str, float]:
        return "strain", sum(0.5 * k * (d - self._dp(state, i, d)) ** 2 for i, k in enumerate(self.k))

    def jump(self, state: State, d_old: float, d_new: float) -> tuple[State, float]:
        # each element's straight path return-mapped, as an elastoplastic spring's
        internal, work = dict(state.internal), 0.0
        for i, part in enumerate(self.parts):
            dp = self._dp(state, i, d_old)
            _, _, internal[f"dp{i}"] = part.return_map(d_new, dp)
            work += part.fy * abs(internal[f"dp{i}"] - dp)
        return State(ELASTIC * len(self.k), internal), work

    def newmark_rows(self, d: float) -> list[tuple[int, tuple[float, ...], float]]:
        """One elastic-perfectly-plastic row per element, each from its plastic deformation at the start."""
        start = self.start(d, 0.0)
        return [(NEWMARK_CORE, (k, fy), self._dp(start, i, d)) for i, (k, fy) in enumerate(zip(self.k, self.fy))]
