"""The decisions taken at an event of a nonsmooth scene (scene.py): which mode each element takes (stick or slip,
yield or unload, contact or separation), decided together where elements share a pair of masses; the velocity
jump of an impact; the state put exactly on the held constraints.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import itertools

import numpy as np

from smdcli.elements import State
from smdcli.solvers.events.scene import TOUCH, Scene, at_level

MAX_IMPACTS_IN_A_SEQUENCE = 10_000


def driven_into(scene: Scene, states: list[State], z: np.ndarray, resolution: float) -> list[int]:
    """The rigid stops held at their limits that the motion runs into faster than resolution (a speed): a stop met
    moving into it at the start, a resting mass the ground's jump drives its wall end into. Each is an impact."""
    from smdcli.elements.stop import FREE, Stop

    n = scene.n
    found = []
    for e, (el, state) in enumerate(zip(scene.elements, states)):
        if isinstance(el.law, Stop) and el.law.rigid and state.mode != FREE:
            rate = float(scene.R[e] @ z[n:2 * n])
            if (rate < -resolution) if state.mode.endswith("min") else (rate > resolution):
                found.append(e)
    return found


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
    which way it moves, or where that is zero to rounding too, its jerk (Motion); a stuck contact on its breakaway
    slips if its force is still growing. `breaking` are contacts an event just let slip, their force at the
    breakaway: they are not stuck again at that instant. on_event(element, kind) records what changed."""
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
        motion = Motion(scene, list(states), z, accel)

        def moving(e: int, sign: float) -> bool:  # d moves the sign's way now: by its rate, or from rest
            if abs(rate[e]) > tolerance:
                return sign * rate[e] > 0
            return motion.toward(e, sign)

        for e, element in enumerate(scene.elements):
            law, state = element.law, states[e]
            table = element.kind
            if table == "friction" and state.mode == STICK and law.regularization is None:
                if abs(rate[e]) > tolerance:  # an impact or a ground jump set it moving: it slips that way
                    states[e] = State(SLIP_PLUS if rate[e] > 0 else SLIP_MINUS)
                    on_event(e, "slip")
                    changed = True
                elif breaks_away(law, tension[e], lambda e=e: motion.tension_rate(e)):
                    states[e] = law.event(state, "slip", d[e], rate[e], tension[e])
                    on_event(e, "slip")
                    changed = True
            elif table == "friction" and state.mode in (SLIP_PLUS, SLIP_MINUS):
                sign = 1.0 if state.mode == SLIP_PLUS else -1.0
                # reversed by a jump of the velocities; a contact that has just broken away has no speed but its
                # rounding (the rate a stuck contact kept, which may read -1e-19 where nothing has moved yet)
                if sign * rate[e] < -tolerance and e not in stopping and e not in breaking:
                    states[e] = State(SLIP_MINUS if sign > 0 else SLIP_PLUS)
                    on_event(e, "slip")
                    changed = True
                elif (sign * rate[e] <= tolerance or e in stopping) and e not in breaking:
                    candidates.append(e)
            elif table == "stop" and law.rigid and state.mode != FREE:
                at_min = state.mode.endswith("min")
                # pulling, or left behind by the ground's jump (its wall end moving off the resting mass)
                if ((tension[e] > 0) if at_min else (tension[e] < 0)) or \
                        ((rate[e] > tolerance) if at_min else (rate[e] < -tolerance)):
                    states[e] = law.event(state, "separation", d[e], rate[e], tension[e])
                    on_event(e, "separation")
                    changed = True
            elif table == "spring":
                settled = law.settle(state, d[e], rate[e], lambda sign, e=e: moving(e, sign))
                if settled is not None:
                    states[e] = settled[0]
                    on_event(e, settled[1])
                    changed = True
        if candidates:
            changed |= _stick_or_slip(scene, states, z, candidates, on_event)
            stopping = ()
        if not changed:
            return states
    return states


class Motion:
    """Which way an element's d moves from rest at z in these states: by its acceleration, or where that is zero
    to rounding (a row a contact has just let go of with the force it held) by its jerk; and the rate of a held
    element's tension. The jerk is found only where it decides."""

    def __init__(self, scene: Scene, states: list[State], z: np.ndarray, accel: np.ndarray):
        self.scene, self.states, self.z, self.accel = scene, states, z, accel
        self._trend = self._size = None

    def trend(self) -> tuple[np.ndarray, np.ndarray]:
        """(jerk, tension rates), once."""
        if self._trend is None:
            self._trend = self.scene.trend(self.states, self.z)
        return self._trend

    def toward(self, e: int, sign: float) -> bool:
        """Whether element e's d leaves rest the sign's way."""
        row = self.scene.R[e]
        a = float(row @ self.accel)
        if self._size is None:
            self._size = self.scene.acceleration_size(self.states, self.z)
        if abs(a) > TOUCH * float(np.abs(row) @ self._size):
            return sign * a > 0
        return sign * float(row @ self.trend()[0]) > 0

    def tension_rate(self, e: int) -> float:
        """The rate of element e's tension."""
        return float(self.trend()[1][e])


def breaks_away(law, tension: float, rate) -> bool:
    """Whether a stuck contact's force passes its breakaway: beyond it, or on it and growing (rate() its rate)."""
    if abs(tension) > law.static * (1 + TOUCH):
        return True
    return abs(tension) >= law.static * (1 - TOUCH) and tension * rate() > 0


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
                motion = Motion(scene, trial, z, accel)
                if any(breaks_away(scene.elements[e].law, tension[e], lambda e=e: motion.tension_rate(e))
                       for e in stuck):
                    continue
                if not all(motion.toward(e, sign) for e, sign in zip(sliding, signs)):
                    continue
                changed = False
                for e in candidates:
                    if trial[e].mode != states[e].mode or e in stuck:
                        on_event(e, "stick" if e in stuck else "slip")
                        changed = True
                    states[e] = trial[e]
                return changed
    return False


def impact(scene: Scene, states: list[State], z: np.ndarray, element: int, e: float) -> np.ndarray:
    """Velocities after a rigid impact at element: d' -> -e d' by an impulse along its row, the held constraints
    kept (their impulses solved with it); the masses' momentum is conserved where the row is internal. A stuck
    friction contact holds nothing through an impact: its force is bounded, so its impulse is zero (it slips
    after, if the impact set it moving)."""
    n = scene.n
    held = [i for i, (el, s) in enumerate(zip(scene.elements, states))
            if el.law.piece(s).held and i != element and el.law.holds_impulse]
    rows = [element] + held
    G = scene.R[rows]
    v = z[n:2 * n]
    MG = scene.Minv @ G.T
    target = np.zeros(len(rows))
    target[0] = -e * (scene.R[element] @ v + scene.belts[element]) - scene.belts[element]
    target[1:] = -scene.belts[held] if held else target[1:]
    W = G @ MG
    if len(rows) == 1:  # the element alone: W is its (positive) effective inverse mass
        impulse = (target - G @ v) / W[0]
    else:
        impulse = np.linalg.lstsq(W, target - G @ v, rcond=None)[0]
    out = z.copy()
    out[n:2 * n] = v + MG @ impulse
    # at the limit, not past it by the rounding of the impact's time (at speed, more than the rounding of d)
    row, x = scene.R[element], out[:n]
    x += scene.Minv @ row * ((scene.elements[element].law.nearest(float(row @ x)) - float(row @ x)) /
                             float(row @ scene.Minv @ row))
    return out


def touch(scene: Scene, states: list[State], z: np.ndarray, element: int, resolution: float) -> str:
    """How a stop is met: "impact" where the motion runs into its limit faster than the run can tell from rest
    (resolution, a speed); else, held there, "rest" where its force would push, "graze" where it would pull (the
    motion leaves again: nothing happens; an integrator read a stop that it had just let go of as met again,
    1e-13 m/s into it or already away from it: for microseconds after a separation the gap, growing as the cube
    of the time, is below the integrator's own error)."""
    n = scene.n
    law = scene.elements[element].law
    d = float(scene.R[element] @ z[:n])
    held = list(states)
    held[element] = law.event(states[element], "rest", d, 0.0, 0.0)
    at_min = law.limit(held[element]) == law.min
    approach = (-1 if at_min else 1) * (float(scene.R[element] @ z[n:2 * n]) + scene.belts[element])
    if approach > resolution:
        return "impact"
    tension = float(scene.evaluate(held, z)[2][element])
    return "graze" if (tension > 0 if at_min else tension < 0) else "rest"


def remaining_flights(scene: Scene, states: list[State], z: np.ndarray, element: int, e: float):
    """The flights an impact at element leaves, if the motion brings it back: (their heights together, their times
    together, the pull), each rebound rising against the pull the motion has now and coming back at e times its
    speed (the geometric series a ball coming to rest obeys), or None where the rebound is not pulled back."""
    n, row = scene.n, scene.R[element]
    rebound = float(row @ z[n:2 * n]) + scene.belts[element]
    pull = float(row @ scene.evaluate(states, z)[3])
    if rebound * pull >= 0 or e >= 1.0:
        return None
    return rebound * rebound / (2 * abs(pull)) / (1 - e * e), 2 * abs(rebound / pull) / (1 - e), abs(pull)


def project(scene: Scene, states: list[State], z: np.ndarray, v_scale: float) -> np.ndarray:
    """Positions and velocities put exactly on the held constraints (a stop's limit, a stuck contact's speed),
    and a slipping contact's speed that is zero to rounding of the run's speeds v_scale (one that slips on from
    rest) made zero, so that its guard starts at its level and the rounding is not read as a touch of it."""
    from smdcli.elements.friction import MINUS, PLUS
    from smdcli.elements.stop import Stop

    n = scene.n
    rate = scene.R @ z[n:2 * n] + scene.belts
    tolerance = TOUCH * max(v_scale, float(np.abs(z[n:2 * n]).max(initial=0.0)))
    held = [e for e, (el, s) in enumerate(zip(scene.elements, states))
            if el.law.piece(s).held or (s.mode in (PLUS, MINUS) and abs(rate[e]) <= tolerance)]
    if not held:
        return z
    G = scene.R[held]
    MG = scene.Minv @ G.T
    z = z.copy()
    v = z[n:2 * n]
    z[n:2 * n] = v + MG @ (np.linalg.pinv(G @ MG) @ (-scene.belts[held] - G @ v))
    stops = [(i, e) for i, e in enumerate(held) if isinstance(scene.elements[e].law, Stop) and
             scene.elements[e].law.piece(states[e]).held]
    if stops:
        Gs = G[[i for i, _ in stops]]
        target = np.array([scene.elements[e].law.limit(states[e]) for _, e in stops])
        MGs = scene.Minv @ Gs.T
        z[:n] = z[:n] + MGs @ (np.linalg.pinv(Gs @ MGs) @ (target - Gs @ z[:n]))
    return z


def accumulation(remaining, length: float, t: float, span: float, impacts: int) -> float | None:
    """When a sequence of impacts ends (persistent contact from then on), or None while its flights are still to be
    followed: once the flights left (remaining_flights) rise together less than the rounding of the scene's length
    scale, or take together less than the rounding of the time, they are summed, not stepped (a ball from 50 m,
    e = 0.8, bounces 72 times before its flights rise less than 7e-13 m). A sequence of MAX_IMPACTS_IN_A_SEQUENCE
    impacts ends too."""
    if remaining is None:
        return None
    heights, duration, _ = remaining
    unseen = heights <= at_level(length, 0.0) or duration <= at_level(abs(t) + span, 0.0)
    return t + duration if unseen or impacts >= MAX_IMPACTS_IN_A_SEQUENCE else None

