"""A scene of nonsmooth elements in one mode: the linear system it is between two events and the quantities its
events watch.

In a mode every element's tension is a Piece (smdcli.elements): stiffness, damping and a constant along its
deformation d, or held (a stuck contact, a persistent stop), its tension then the constraint's force. The held
rows G (d' = 0) are kept by the forces G^T mu with mu = -(G M^-1 G^T)^-1 G M^-1 F, so the motion is

    M x'' = P F,   P = I - G^T (G M^-1 G^T)^-1 G M^-1,   F = B u(t) - Kt x - Ct v + g,

linear in z = [x, v, w] (w the force generators' state): z' = A z + b, b constant. Every quantity an event
watches (d, d', a held element's tension) is a row times z plus a constant. Shared by the exact event-driven
solver (piecewise.py) and the integrators' event-driven driver (integrated.py); the decisions at an event
are decisions.py's.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from smdcli.elements import State
from smdcli.elements.base import D, RATE
from smdcli.model import Model

TOUCH = 1e-12  # relative slack with which a point on a yield surface or at zero speed counts as there
EPS = float(np.finfo(float).eps)


def at_level(size, const: float):
    """How close to its level a guard's value is rounding of it: 64 ulps of the terms it sums (row |z| + |const|)."""
    return 64 * EPS * (size + abs(const))


def event_root(value, lo: float, hi: float, scale: float) -> float:
    """The root of value in [lo, hi] (a sign change there) to rounding: relative to the root, or to `scale` (the
    step's length) where the root is near zero, so that a root at the start of a step ends in a few dozen steps."""
    from scipy.optimize import brentq

    return float(brentq(value, lo, hi, xtol=2 * EPS * scale, rtol=4 * EPS, maxiter=400))


@dataclass
class Mode:
    """One mode of the scene as linear algebra: z' = A z + b; rows for each element's d, d' and tension."""

    key: tuple
    a_key: tuple  # what A depends on (the stiffnesses, dampings and held rows): modes sharing it share a flow
    A: np.ndarray  # (s, s)
    b: np.ndarray  # (s,)
    d_rows: np.ndarray  # (E, s): d = d_rows z
    rate_rows: np.ndarray  # (E, s): d' = rate_rows z + belts
    tension_rows: np.ndarray  # (E, s): T = tension_rows z + tension_const (held ones: the constraint's force)
    tension_const: np.ndarray  # (E,)
    acceleration_rows: np.ndarray  # (n, s): x'' = acceleration_rows z + acceleration_const
    acceleration_const: np.ndarray
    held: tuple[int, ...]
    guards: list = None  # (element, Guard, row, constant): the guard's quantity less its level = row z + constant
    Kt: np.ndarray = None  # the mode's stiffness, damping and constant force, for integrators (integrated.py)
    Ct: np.ndarray = None
    g: np.ndarray = None
    hold: tuple = None  # (M^-1 G^T, (G M^-1 G^T)^+, G) of the held rows, or None
    _guard_table: tuple = None

    @property
    def guard_table(self) -> tuple:
        """All guards at once, signed by direction: (rows (2g, s), constants (2g,), |rows| (g, s)), the first g rows
        the guards' values (rows z + constants), the next g their rates."""
        if self._guard_table is None:
            direction = np.array([guard.direction for _, guard, _, _ in self.guards], dtype=float)
            rows = np.array([row for _, _, row, _ in self.guards]).reshape(len(self.guards), len(self.b))
            consts = np.array([const for _, _, _, const in self.guards], dtype=float)
            signs = np.concatenate([direction, direction])
            self._guard_table = (np.vstack([rows, rows @ self.A]) * signs[:, None],
                                 np.concatenate([consts, rows @ self.b]) * signs, np.abs(rows))
        return self._guard_table


class Scene:
    """The fixed part of a nonsmooth model: matrices, element rows, and the force generators' blocks."""

    forces_at_t = False  # a subclass that reads its forces at t takes forces without a generator (an empty block)

    def __init__(self, model: Model):
        self.model = model
        self.n = model.n
        self.elements = model.nonsmooth
        self.E = len(self.elements)
        self.R = np.array([e.row for e in self.elements]).reshape(self.E, self.n)
        self.belts = np.array([e.belt for e in self.elements], dtype=float)
        self.Minv = model.Minv
        exos = [s.exo() for s in model.signals]
        if not self.forces_at_t and None in exos:
            raise AssertionError(f"{model.source}: a force without a generator reached an exact scene (held first)")
        self.exos = exos
        blocks, col = [], 2 * self.n
        for signal, exo in zip(model.signals, exos):
            m = exo.S.shape[0] if exo is not None else 0  # none: the force is read at t (forces_at_t)
            blocks.append((col, col + m, signal, exo))
            col += m
        self.size = col
        self.blocks = blocks
        self._modes: dict = {}

    def reseed(self, z: np.ndarray, t: float) -> None:
        """The force generators' state just after t (their right limits: a jump at t is taken)."""
        for lo, hi, signal, _ in self.blocks:
            z[lo:hi] = signal.exo_state(t)

    def mode(self, states: list[State]) -> Mode:
        """The linear system of the scene in these states (cached by the discrete modes and their constants)."""
        pieces = [e.law.piece(s) for e, s in zip(self.elements, states)]
        key = tuple((p.stiffness, p.damping, p.constant, p.held, p.guards) for p in pieces)
        cached = self._modes.get(key)
        if cached is None:
            cached = self._modes[key] = self._build(key, pieces)
            cached.guards = [(e, guard, *self.guard_row(cached, e, guard))
                             for e, p in enumerate(pieces) for guard in p.guards]
        return cached

    def _build(self, key: tuple, pieces) -> Mode:
        n, s, E, R = self.n, self.size, self.E, self.R
        model = self.model
        Kt, Ct = model.K.copy(), model.C.copy()
        g = np.zeros(n)
        for e, p in enumerate(pieces):
            if p.held:
                continue
            r = R[e]
            if p.stiffness:
                Kt += p.stiffness * np.outer(r, r)
            if p.damping:
                Ct += p.damping * np.outer(r, r)
            g -= (p.constant + p.damping * self.belts[e]) * r
        # F = Fz z + g: the force on the masses, less the held elements' constraint forces
        Fz = np.zeros((n, s))
        Fz[:, :n], Fz[:, n:2 * n] = -Kt, -Ct
        for (lo, hi, _, exo), column in zip(self.blocks, model.B.T):
            if exo is not None:
                Fz[:, lo:hi] = np.outer(column, exo.g)
        held = tuple(e for e, p in enumerate(pieces) if p.held)
        MF, Mg = self.Minv @ Fz, self.Minv @ g
        tension_rows = np.zeros((E, s))
        tension_const = np.zeros(E)
        hold = None
        if held:
            G = R[list(held)]
            MG = self.Minv @ G.T
            S = G @ MG
            S_pinv = self._shared_inverse(S, held)
            hold = (MG, S_pinv, G)
            mu_z, mu_g = -S_pinv @ (G @ MF), -S_pinv @ (G @ Mg)
            acc_z, acc_g = MF + MG @ mu_z, Mg + MG @ mu_g
            tension_rows[list(held)] = -mu_z
            tension_const[list(held)] = -mu_g
        else:
            acc_z, acc_g = MF, Mg
        A = np.zeros((s, s))
        A[:n, n:2 * n] = np.eye(n)
        A[n:2 * n] = acc_z
        for lo, hi, _, exo in self.blocks:
            if exo is not None:
                A[lo:hi, lo:hi] = exo.S
        b = np.zeros(s)
        b[n:2 * n] = acc_g
        d_rows = np.zeros((E, s))
        d_rows[:, :n] = R
        rate_rows = np.zeros((E, s))
        rate_rows[:, n:2 * n] = R
        for e, p in enumerate(pieces):
            if not p.held:
                tension_rows[e] = p.stiffness * d_rows[e] + p.damping * rate_rows[e]
                tension_const[e] = p.constant + p.damping * self.belts[e]
        a_key = tuple((p.stiffness, p.damping, p.held) for p in pieces)
        return Mode(key, a_key, A, b, d_rows, rate_rows, tension_rows, tension_const, acc_z, acc_g, held,
                    Kt=Kt, Ct=Ct, g=g, hold=hold)

    def _shared_inverse(self, S: np.ndarray, held: tuple[int, ...]) -> np.ndarray:
        """S^-1 for the held rows' forces, or where some are redundant (two contacts on one row) the weighted
        pseudo-inverse W (W S W)^+ W, W = diag(sqrt(capacity)), that shares a load among them in proportion to
        what each can hold: stuck contacts by their breakaway forces, a stop (unbounded) taking all but 1e-6."""
        capacities = [self.elements[e].law.capacity for e in held]
        finite = [c for c in capacities if c is not None]
        unbounded = 1e6 * max(finite) if finite else 1.0
        w = np.sqrt(np.array([unbounded if c is None else c for c in capacities], dtype=float))
        return w[:, None] * np.linalg.pinv(w[:, None] * S * w[None, :]) * w[None, :]

    def trend(self, states: list[State], z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the masses' jerk, the tensions' rates) at z in these states: what decides a motion whose rate and
        acceleration are both zero (a row that a contact has just stopped holding, with the same force)."""
        mode = self.mode(states)
        zdot = mode.A @ z + mode.b
        return (mode.A @ zdot)[self.n:2 * self.n], mode.tension_rows @ zdot

    def acceleration_size(self, states: list[State], z: np.ndarray) -> np.ndarray:
        """The size of the terms each mass's acceleration sums (the scale of its rounding)."""
        mode = self.mode(states)
        return np.abs(mode.acceleration_rows) @ np.abs(z) + np.abs(mode.acceleration_const)

    # ---------------------------------------------------------------------------------- quantities
    def quantities(self, mode: Mode, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(d, d', T) of every element at z."""
        return mode.d_rows @ z, mode.rate_rows @ z + self.belts, mode.tension_rows @ z + mode.tension_const

    def live(self, states: list[State], z: np.ndarray) -> list[State]:
        """The states with any internal variables z carries (none here: see SmoothScene)."""
        return states

    def evaluate(self, states: list[State], z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(d, d', T, x'') at z in these states: what the decisions at an event look at."""
        mode = self.mode(states)
        d, rate, tension = self.quantities(mode, z)
        return d, rate, tension, mode.acceleration_rows @ z + mode.acceleration_const

    def guard_row(self, mode: Mode, element: int, guard) -> tuple[np.ndarray, float]:
        """(row, constant) with the guard's quantity minus its level = row z + constant."""
        if guard.quantity == D:
            return mode.d_rows[element], -guard.level
        if guard.quantity == RATE:
            return mode.rate_rows[element], self.belts[element] - guard.level
        return mode.tension_rows[element], mode.tension_const[element] - guard.level
