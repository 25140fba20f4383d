"""A scene of nonsmooth elements in one mode: the linear system it is between two events, the quantities its
events watch, and the decisions taken at an event (stick or slip, impact, rest, separation).

In a mode every element's tension is a Piece (smdcli.elements): stiffness, damping and a constant along its
deformation d, or held (a stuck contact, a persistent stop), its tension then the constraint's force. The held
rows G (d' = 0) are kept by the forces G^T mu with mu = -(G M^-1 G^T)^-1 G M^-1 F, so the motion is

    M x'' = P F,   P = I - G^T (G M^-1 G^T)^-1 G M^-1,   F = B u(t) - Kt x - Ct v + g,

linear in z = [x, v, w] (w the force generators' state): z' = A z + b, b constant. Every quantity an event
watches (d, d', a held element's tension) is a row times z plus a constant. Shared by the exact event-driven
solver (piecewise.py) and the integrators' event-driven driver (nonsmooth_ivp.py).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import itertools
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
    Kt: np.ndarray = None  # the mode's stiffness, damping and constant force, for integrators (nonsmooth_ivp.py)
    Ct: np.ndarray = None
    g: np.ndarray = None
    hold: tuple = None  # (M^-1 G^T, (G M^-1 G^T)^+, G) of the held rows, or None


class Scene:
    """The fixed part of a nonsmooth model: matrices, element rows, and the force generators' blocks."""

    def __init__(self, model: Model):
        self.model = model
        self.n = model.n
        self.elements = model.nonsmooth
        self.E = len(self.elements)
        self.R = np.array([e.row for e in self.elements]).reshape(self.E, self.n)
        self.belts = np.array([e.belt for e in self.elements], dtype=float)
        self.Minv = model.Minv
        exos = [s.exo() for s in model.signals]
        self.exos = exos
        self.size = 2 * self.n + sum(e.S.shape[0] for e in exos)
        blocks, col = [], 2 * self.n
        for signal, exo in zip(model.signals, exos):
            m = exo.S.shape[0]
            blocks.append((col, col + m, signal, exo))
            col += m
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
            S_pinv = np.linalg.pinv(S)  # a redundant constraint (two contacts on one row) shares its force
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


# -------------------------------------------------------------------------------- decisions at events


def scale_of(values: np.ndarray) -> float:
    """A magnitude to judge 'zero' against."""
    return max(float(np.max(np.abs(values), initial=0.0)), 1e-300)


def consistent(scene: Scene, states: list[State], z: np.ndarray, t: float, on_event,
               stopping: tuple[int, ...] = (), v_scale: float = 0.0, breaking: tuple[int, ...] = ()) -> list[State]:
    """The modes the scene takes at z: every element's instantaneous conditions checked until none changes. A
    stuck contact whose force passes its breakaway slips; a persistent stop that would pull separates; a spring on
    its yield surface loading outward yields, one unloading turns elastic; slipping contacts at zero speed stick or
    reverse, decided together (a small complementarity problem: every subset of them tried as stuck, the largest
    consistent one kept; `stopping` are contacts whose speed an event just found at zero, whatever its rounding).
    A rate within TOUCH of v_scale (the run's speeds) is zero: the sign of the element's acceleration decides
    which way it moves; `breaking` are contacts an event just let slip, their force at the breakaway: they are not
    stuck again at that instant. on_event(element, kind) records what changed."""
    from smdcli.elements.elastoplastic import ELASTIC
    from smdcli.elements.friction import MINUS as SLIP_MINUS
    from smdcli.elements.friction import PLUS as SLIP_PLUS
    from smdcli.elements.friction import STICK
    from smdcli.elements.stop import FREE

    states = list(states)
    tolerance = TOUCH * max(v_scale, scale_of(z[scene.n:2 * scene.n]), scale_of(scene.model.v0))
    for _ in range(4 * scene.E + 4):
        d, rate, tension, accel = scene.evaluate(states, z)
        changed = False
        candidates = []

        def moving(e: int, sign: float) -> bool:  # d moves the sign's way now: by its rate, or from rest
            if abs(rate[e]) > tolerance:
                return sign * rate[e] > 0
            return sign * float(scene.R[e] @ accel) > 0

        for e, element in enumerate(scene.elements):
            law, state = element.law, states[e]
            table = element.kind
            if table == "friction" and state.mode == STICK and law.regularization is None:
                if abs(rate[e]) > tolerance:  # an impact or a ground jump set it moving: it slips that way
                    states[e] = State(SLIP_PLUS if rate[e] > 0 else SLIP_MINUS)
                    on_event(e, "slip")
                    changed = True
                elif abs(tension[e]) > law.static * (1 + TOUCH):
                    states[e] = law.event(state, "slip", d[e], rate[e], tension[e])
                    on_event(e, "slip")
                    changed = True
            elif table == "friction" and state.mode in (SLIP_PLUS, SLIP_MINUS):
                sign = 1.0 if state.mode == SLIP_PLUS else -1.0
                if sign * rate[e] < -tolerance and e not in stopping:  # reversed by a jump of the velocities
                    states[e] = State(SLIP_MINUS if sign > 0 else SLIP_PLUS)
                    on_event(e, "slip")
                    changed = True
                elif (sign * rate[e] <= tolerance or e in stopping) and e not in breaking:
                    candidates.append(e)
            elif table == "stop" and law.rigid and state.mode != FREE:
                at_min = state.mode.endswith("min")
                if (tension[e] > 0) if at_min else (tension[e] < 0):
                    states[e] = law.event(state, "separation", d[e], rate[e], tension[e])
                    on_event(e, "separation")
                    changed = True
            elif table == "spring" and hasattr(law, "core"):
                if state.mode == ELASTIC:
                    side = _at_surface(law, state, d[e])
                    if side and moving(e, side):
                        states[e] = law.event(state, "yield", d[e], rate[e], tension[e])
                        on_event(e, "yield")
                        changed = True
                else:
                    sign = 1.0 if state.mode.endswith("+") else -1.0
                    if not moving(e, sign):
                        states[e] = law.event(state, "unload", d[e], rate[e], tension[e])
                        on_event(e, "unload")
                        changed = True
        if candidates:
            changed |= _stick_or_slip(scene, states, z, candidates, on_event)
            stopping = ()
        if not changed:
            return states
    return states


def _at_surface(law, state: State, d: float) -> int:
    """+1 or -1 where an elastic spring's tension is on its yield surface (to rounding), else 0."""
    core = law.core
    trial = core.k * (d - state.internal["dp"])
    if abs(trial) < core.fy * (1 - TOUCH):
        return 0
    return 1 if trial > 0 else -1


def _stick_or_slip(scene: Scene, states: list[State], z: np.ndarray, candidates: list[int], on_event) -> bool:
    """Slipping contacts at zero relative speed, decided together: the largest subset that can stick (each held
    contact's force within its breakaway) with the others slipping each in a direction its own acceleration then
    takes (Coulomb's complementarity, by enumeration: a scene holds a few contacts)."""
    from smdcli.elements.friction import MINUS, PLUS, STICK

    for size in range(len(candidates), -1, -1):
        for stuck in itertools.combinations(candidates, size):
            sliding = [e for e in candidates if e not in stuck]
            for signs in itertools.product((1.0, -1.0), repeat=len(sliding)):
                trial = list(states)
                for e in stuck:
                    trial[e] = State(STICK)
                for e, sign in zip(sliding, signs):
                    trial[e] = State(PLUS if sign > 0 else MINUS)
                _, _, tension, accel = scene.evaluate(trial, z)
                if not all(abs(tension[e]) <= scene.elements[e].law.static * (1 + TOUCH) for e in stuck):
                    continue
                if not all(sign * float(scene.R[e] @ accel) > 0 for e, sign in zip(sliding, signs)):
                    continue
                changed = False
                for e in candidates:
                    if trial[e].mode != states[e].mode or e in stuck:
                        on_event(e, "stick" if e in stuck else "slip")
                        changed = True
                    states[e] = trial[e]
                return changed
    return False


def impact(scene: Scene, states: list[State], z: np.ndarray, element: int, restitution: float) -> np.ndarray:
    """Velocities after a rigid impact at element: d' -> -e d' by an impulse along its row, the held constraints
    kept (their impulses solved with it); the masses' momentum is conserved where the row is internal. A stuck
    friction contact holds nothing through an impact: its force is bounded, so its impulse is zero (it slips
    after, if the impact set it moving)."""
    n = scene.n
    held = [e for e, (el, s) in enumerate(zip(scene.elements, states))
            if el.law.piece(s).held and e != element and el.law.holds_impulse]
    rows = [element] + held
    G = scene.R[rows]
    v = z[n:2 * n]
    MG = scene.Minv @ G.T
    target = np.zeros(len(rows))
    target[0] = -restitution * (scene.R[element] @ v + scene.belts[element]) - scene.belts[element]
    target[1:] = -scene.belts[held] if held else target[1:]
    impulse = np.linalg.lstsq(G @ MG, target - G @ v, rcond=None)[0]
    out = z.copy()
    out[n:2 * n] = v + MG @ impulse
    return out
