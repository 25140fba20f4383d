"""Piecewise-linear scenes solved exactly, event to event.

Between two events (a yield, an unloading, a stick or slip, a contact, an impact, a separation) a scene of
elastoplastic and bilinear springs, Coulomb friction and stops is linear with constant forcing terms (scene.py):
z' = A z + b, whose flow z(t) = E(t) z0 + Phi(t) b is one matrix exponential ([[A, I], [0, 0]] t). Each event
is where a quantity linear in z crosses a level, found on the exact flow: the flow is sampled at substeps short
enough to see every crossing (an eighth of the fastest mode's period, the output step at most), a crossing
bracketed, a touch without a crossing caught where the quantity's slope changes sign, and the time found by
Brent's method to rounding (crossings.py). The events' decisions (modes.consistent, modes.impact) set the next mode.
Whole output steps are taken in batches until the first that may hold an event (batches.py).

A rigid stop's impacts that accumulate (a ball coming to rest) are followed one by one while the flights left could
be seen: once they rise together less than the rounding of the scene's length scale, or take less than the rounding
of the time, they are summed as the geometric series they are (decisions.accumulation) and the stop holds
(persistent contact) from that accumulation time, recorded as "rest".

The energy balance is integrated on the same pieces (Gauss-Legendre, 8 nodes a substep, exact for the
quadratic powers of a linear flow): dissipated by dampers, hysteretic (yielding), friction, impact (lost at
impacts, and in a compliant stop's damper), input; stored: kinetic, strain, contact.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
import time

import numpy as np

from smdcli.elements import State
from smdcli.elements.base import EVENT_KINDS, KINK
from smdcli.model import Model
from smdcli.model.nonsmooth import whole_tension
from smdcli.result import Result, SolverStats
from smdcli.solvers.base import make_result
from smdcli.solvers.events.batches import Batches
from smdcli.solvers.events.crossings import Crossings
from smdcli.solvers.exact.flow import Flow
from smdcli.solvers.exact.hold import first_order_hold, halved, held_reason, hold_error, hold_response_error
from smdcli.solvers.events.decisions import accumulation, consistent, driven_into, impact, project, remaining_flights, \
    touch
from smdcli.solvers.events.scene import TOUCH, Mode, Scene
from smdcli.solvers.events.record import Outputs, step_integrals

MAX_EVENTS_AT_ONE_TIME = 200  # a mode that cannot settle at one instant is a scene smd cannot solve
MAX_SUBSTEPS = 2_000_000  # substeps a run may take (about 100 us each): a mode faster than that is refused


class PiecewiseFailed(Exception):
    """A scene the event-driven solver cannot advance (chattering at one instant)."""


UNSETTLED = "do not settle"  # the failure of events that cannot be ordered at one instant (auto goes on from it)
MAX_EVENTS_IN_AN_INSTANT = 2_000  # events within INSTANT output steps of the first: a chatter no step resolves
INSTANT = 1e-6


class Pileup:
    """Events that do not let a run go on: more than MAX_EVENTS_AT_ONE_TIME at one instant, or more than
    MAX_EVENTS_IN_AN_INSTANT within INSTANT output steps of the first (a yield force far below the displacement's
    rounding yields and unloads 1e-13 s apart without end)."""

    def __init__(self, h_out: float):
        self.span = INSTANT * h_out
        self.last, self.same = None, 0  # the last event's time, the events at it after the first
        self.start, self.count = None, 0  # the window's first event's time, the events in it

    def add(self, t: float, events: list) -> str | None:
        """Why the events, one more at t, do not settle (events: the run's, the last naming the element); None while
        they may."""
        self.same = self.same + 1 if t == self.last else 0
        self.last = t
        if self.start is not None and t - self.start <= self.span:
            self.count += 1
        else:
            self.start, self.count = t, 1
        what = f" ({events[-1][1]} {events[-1][2]} again and again)" if events else ""
        if self.same > MAX_EVENTS_AT_ONE_TIME:
            return f"events at t = {t:.6g} s {UNSETTLED}{what}"
        if self.count > MAX_EVENTS_IN_AN_INSTANT:
            return f"events at t = {t:.6g} s {UNSETTLED}: {self.count} events within {t - self.start:.2g} s{what}"
        return None


class PiecewiseRun(Crossings, Batches):
    """One exact event-driven run over an output grid."""

    scene_class = Scene

    def __init__(self, model: Model, grid: np.ndarray):
        self.model, self.grid = model, grid
        self.scene = self.scene_class(model)
        self.n = model.n
        self.N = len(grid)
        self.flows: dict[tuple, Flow] = {}
        self.events: list[tuple[float, str, str]] = []
        self.event_points: list = []  # (x, v, tension) at each event
        self.velocity_before: dict[int, np.ndarray] = {}  # an impact's velocities before its jump, by event index
        self.energy_terms = ("dissipated", "input", "hysteretic", "friction", "impact")
        self.cumulative = dict.fromkeys(self.energy_terms, 0.0)
        self.impacts: dict[int, list[tuple[float, float]]] = {}
        self.v_scale = float(np.abs(model.v0).max(initial=0.0))  # the run's speeds, as far as seen
        self.x_scale = float(np.abs(model.x0).max(initial=0.0))  # and its positions
        self.damped = bool(np.any(model.C))

    def flow(self, mode: Mode, t: float) -> Flow:
        """The cached flow of a mode's A, entered at t; PiecewiseFailed where A overflows double precision."""
        found = self.flows.get(mode.a_key)
        if found is None:
            if not np.isfinite(mode.A).all():  # a force or stiffness beyond double precision over a mass
                raise PiecewiseFailed(f"at t = {t:.6g} s the scene's equations overflow double precision (NaN or "
                                      "inf in its matrix): check its numbers and their units")
            found = self.flows[mode.a_key] = Flow(mode.A)
        return found

    # ------------------------------------------------------------------------------------------ run
    def run(self):
        """x, v, a (N, n) and the elements' history (tensions, internal variables, events, energy) on the grid."""
        scene, n, grid = self.scene, self.n, self.grid
        model = self.model
        z = np.zeros(scene.size)
        z[:n], z[n:2 * n] = model.x0, model.v0
        t = float(grid[0])
        scene.reseed(z, t)
        states = [e.law.start(float(e.row @ model.x0), float(e.row @ model.v0 + e.belt)) for e in scene.elements]
        states, z = self.start(states, z, t)
        outputs = Outputs(self, grid)
        outputs.store(0, z, states)
        span = float(grid[-1] - grid[0])
        h_out = span / (self.N - 1) if self.N > 1 else 0.0
        breaks = self.breaks()
        self.break_times = np.array([time_ for time_, _ in breaks], dtype=float)
        self.break_jumps = np.array([jump is not None for _, jump in breaks], dtype=bool)
        b_next = 0
        self.whole_steps = np.abs(np.diff(grid) - h_out) <= 1e-9 * h_out  # grid steps of h_out, by their ends
        k = 1
        pileup = Pileup(h_out)
        while k < self.N:
            mode = scene.mode(states)
            flow = self.flow(mode, t)
            while b_next < len(breaks) and breaks[b_next][0] <= t:
                b_next += 1
            break_time = breaks[b_next][0] if b_next < len(breaks) else math.inf
            target = min(float(grid[k]), break_time)
            h_sub = h_out if flow.omega * h_out <= math.pi / 4 else (math.pi / 4) / flow.omega
            if (float(grid[-1]) - t) / h_sub > MAX_SUBSTEPS:
                raise PiecewiseFailed(f"the fastest mode ({flow.omega:.3g} rad/s) needs {(grid[-1] - t) / h_sub:.3g} "
                                      f"substeps of {h_sub:.3g} s to see every event from t = {t:.6g} s (limit "
                                      f"{MAX_SUBSTEPS:.0e}); shorten the run or check the scene's units")
            if h_sub == h_out:  # whole output steps: as many as no event interrupts, at once
                batch = self.batch(flow, mode, states, z, t, k, breaks, b_next, h_out, outputs)
                if batch is not None:
                    states, z, t, k = batch
                    continue
            lands = target - t <= h_sub * (1 + 1e-9)
            step = target - t if lands else h_sub
            if abs(step - h_out) <= 1e-9 * h_out:
                step = h_out  # a grid difference that is the step up to the rounding of the grid's times
            keep = step == h_sub or step == h_out
            z_new = flow.at(z, mode.b, step, keep)
            found = self.first_crossing(flow, mode, z, z_new, step)
            if found is not None:
                tau, element, guard = found
                self.integrate(flow, mode, states, z, tau, keep=False)
                t_event = t + tau if tau < step or not lands else target
                z = flow.at(z, mode.b, tau)
                unsettled = pileup.add(t_event, self.events)
                if unsettled:
                    raise PiecewiseFailed(unsettled)
                t = t_event
                states, z = self.apply(states, z, t, element, guard.kind)
                if lands and tau == step:  # the event is on the target: the target is passed after it
                    states, z, k = self.land(states, z, t, k, target, break_time, breaks, b_next, outputs)
                continue
            self.integrate(flow, mode, states, z, step, keep)
            z = z_new
            if lands:
                t = target
                states, z, k = self.land(states, z, t, k, target, break_time, breaks, b_next, outputs)
            else:
                t += step
        self.sort_events()
        return outputs.finish()

    def land(self, states, z, t, k, target, break_time, breaks, b_next, outputs):
        """At a target: a break crossed (right limits), an output point stored."""
        if target == break_time:
            states, z = self.cross_break(states, z, t, breaks[b_next][1])
        if target == float(self.grid[k]):
            outputs.store(k, z, states)
            k += 1
        return states, z, k

    # ------------------------------------------------------------------------------------- events
    def record(self, t: float, element: int, kind: str) -> None:
        """An event on /events."""
        assert kind in EVENT_KINDS, kind
        self.events.append((t, self.scene.elements[element].path, kind))
        self.event_points.append(None)  # its state, once the decisions settle (place_events)

    def settle(self, states, z: np.ndarray, t: float, stopping: tuple[int, ...] = (),
               breaking: tuple[int, ...] = ()):
        """The consistent modes at (t, z), events recorded."""
        # the run's speeds, or where nothing has moved yet, what its accelerations give in an output step: a rate
        # of 1e-19 m/s left by rounding on a contact at rest is no motion
        span = float(self.grid[-1] - self.grid[0]) / max(self.N - 1, 1)
        self.x_scale = max(self.x_scale, float(np.abs(z[:self.n]).max(initial=0.0)))
        self.v_scale = max(self.v_scale, float(np.abs(z[self.n:2 * self.n]).max(initial=0.0)),
                           float(self.scene.acceleration_size(states, z).max(initial=0.0)) * span)
        states = consistent(self.scene, states, z, t, lambda e, kind: self.record(t, e, kind), stopping,
                            self.v_scale, breaking)
        self.place_events(states, z)
        return states

    def place_events(self, states, z: np.ndarray) -> None:
        """The state of the events recorded since the last settled: positions, velocities and the elements' tensions
        as the decisions left them (a yield's corner, an impact's contact point), for what samples miss."""
        if self.event_points and self.event_points[-1] is None:
            n = self.n
            d, _, tension, _ = self.scene.evaluate(states, z)
            point = (z[:n].copy(), z[n:2 * n].copy(), whole_tension(self.scene.elements, tension, d))
            for i in range(len(self.event_points) - 1, -1, -1):
                if self.event_points[i] is not None:
                    break
                self.event_points[i] = point

    def event_arrays(self) -> dict:
        """The events' states as NonsmoothHistory's event_x, event_v (and event_v_before), event_tension."""
        n, E = self.n, len(self.scene.elements)
        placed = [p for p in self.event_points if p is not None]
        if len(placed) != len(self.event_points):  # an event never settled (a failed run): no states to give
            return {}
        v = np.array([p[1] for p in placed]).reshape(-1, n)
        before = v.copy()
        for i, jumped_from in self.velocity_before.items():
            before[i] = jumped_from
        return {"event_x": np.array([p[0] for p in placed]).reshape(-1, n), "event_v": v, "event_v_before": before,
                "event_tension": np.array([p[2] for p in placed]).reshape(-1, E)}

    def sort_events(self) -> None:
        """The events in time order, their states with them."""
        order = sorted(range(len(self.events)), key=lambda i: self.events[i][0])
        self.events = [self.events[i] for i in order]
        self.event_points = [self.event_points[i] for i in order]
        position = {old: new for new, old in enumerate(order)}
        self.velocity_before = {position[i]: v for i, v in self.velocity_before.items()}

    def apply(self, states, z: np.ndarray, t: float, element: int, kind: str):
        """The modes and state after an event of element: (states, z)."""
        scene = self.scene
        if kind == KINK:  # a smooth law's kink: the integrator restarts, nothing else happens
            return states, z
        if kind == "impact":
            return self.impact(states, z, t, element)
        stopping = breaking = ()
        if kind == "stick":  # a candidate: decided with every other contact at zero speed (consistent)
            stopping = (element,)
        else:
            breaking = (element,) if kind == "slip" else ()
            d, rate, tension, _ = scene.evaluate(states, z)
            states = list(states)
            states[element] = scene.elements[element].law.event(states[element], kind, float(d[element]),
                                                                  float(rate[element]), float(tension[element]))
            self.record(t, element, kind)
        states = self.settle(states, z, t, stopping, breaking)
        return states, self.project(states, z)

    def impact(self, states, z: np.ndarray, t: float, element: int):
        """A rigid impact: velocities jumped, the energy lost booked; an accumulating sequence ends at rest."""
        scene, n = self.scene, self.n
        law = scene.elements[element].law
        before = self.kinetic(z)
        speed = abs(float(scene.R[element] @ z[n:2 * n]))
        met = touch(scene, states, z, element, self.speed_resolution())
        if met == "graze":
            return states, z
        history = self.impacts.setdefault(element, [])
        rest_at, resting = None, True  # met at rest, pressed on: persistent contact, no impact
        if met == "impact":
            v_before = z[n:2 * n].copy()
            z = impact(scene, states, z, element, law.rebound)
            self.record(t, element, "impact")
            self.velocity_before[len(self.events) - 1] = v_before  # the jump, for what draws the state
            history.append((t, speed))
            remaining = remaining_flights(scene, states, z, element, law.rebound)
            # the scene's length: its positions so far, and the rise of the sequence's first flight
            length = self.x_scale if remaining is None else max(self.x_scale, history[0][1] ** 2 / (2 * remaining[2]))
            rest_at = accumulation(remaining, length, t, float(self.grid[-1] - self.grid[0]), len(history))
            resting = law.rebound == 0 or rest_at is not None or speed <= 1e-14 * max(history[0][1], 1e-300)
        states = list(states)
        if resting:
            states[element] = law.event(states[element], "rest", float(scene.R[element] @ z[:n]), 0.0, 0.0)
            z = self.project(states, z)
            self.record(t if rest_at is None else rest_at, element, "rest")
            history.clear()
        self.cumulative["impact"] += before - self.kinetic(z)
        states = self.settle(states, z, t)
        return states, self.project(states, z)

    def speed_resolution(self) -> float:
        """The speed below which the run cannot tell a motion from rest: the rounding of the run's speeds."""
        return TOUCH * self.v_scale

    def project(self, states, z: np.ndarray) -> np.ndarray:
        """z put exactly on the held constraints (decisions.project)."""
        return project(self.scene, states, z, self.v_scale)

    def start(self, states, z: np.ndarray, t: float):
        """The modes at the start: a rigid stop met moving into it is an impact at once; then consistent."""
        states, z = self.strike(states, z, t, 0.0)
        states = self.settle(states, z, t)
        return states, self.project(states, z)

    def strike(self, states, z: np.ndarray, t: float, resolution: float):
        """Each rigid stop held at its limit that the motion runs into faster than resolution struck at once (an
        impact, its restitution's rebound): at the start, or where the ground's jump drives its wall end into the
        mass resting on it."""
        from smdcli.elements.stop import FREE

        for e in driven_into(self.scene, states, z, resolution):
            if states[e].mode != FREE:  # not let go by an impact struck before it
                states = list(states)
                states[e] = State(FREE)
                states, z = self.impact(states, z, t, e)
        return states, z

    def breaks(self) -> list[tuple[float, object]]:
        """Force discontinuities (reseed the generators) and ground jumps (the state jumps), in time order."""
        t0, t1 = float(self.grid[0]), float(self.grid[-1])
        merged: dict[float, object] = {float(t): None for t in self.model.breakpoints(t0, t1)}
        for t, dx, dv in self.model.jumps:
            if t0 < t <= t1:
                previous = merged.get(float(t))
                merged[float(t)] = (dx, dv) if previous is None else (previous[0] + dx, previous[1] + dv)
        return sorted(merged.items())

    def cross_break(self, states, z: np.ndarray, t: float, jump):
        """At a break: the generators reseeded (a force's jump), or the state jumped (the ground's)."""
        z = z.copy()
        self.scene.reseed(z, t)
        if jump is None and any(el.law.piece(s).held for el, s in zip(self.scene.elements, states)):
            # a force's jump may pass a stuck contact's breakaway or pull a held stop away: its guard is not
            # crossed along a flow but jumped over here
            states = self.settle(states, z, t)
            z = self.project(states, z)
        if jump is not None:  # the wall ends of the elements to ground jump: the ground does that work
            dx, dv = jump
            before = sum(self.stored(states, z))
            d_old = self.scene.R @ z[:self.n]
            z[:self.n] += dx
            z[self.n:2 * self.n] += dv
            d_new = self.scene.R @ z[:self.n]
            lost = 0.0  # what the elements dissipate on the way (a spring yielding through the jump)
            states = list(states)
            for e, element in enumerate(self.scene.elements):
                states[e], loss = element.law.jump(states[e], float(d_old[e]), float(d_new[e]))
                lost += loss
            self.cumulative["hysteretic"] += lost
            self.cumulative["input"] += sum(self.stored(states, z)) - before + lost
            states, z = self.strike(states, z, t, self.speed_resolution())
            states = self.settle(states, z, t)
            z = self.project(states, z)
        return states, z

    def stored(self, states, z: np.ndarray) -> tuple[float, float, float]:
        """(kinetic, strain, contact) energy at z: the linear springs' and the elements' own."""
        n = self.n
        x = z[:n]
        strain = 0.5 * float(x @ self.model.K @ x)
        if self.model.cubic is not None:
            strain += float((0.25 * self.model.cubic.coef * (self.model.cubic.D @ x) ** 4).sum())
        contact = 0.0
        d = self.scene.R @ x
        for e, (element, state) in enumerate(zip(self.scene.elements, self.scene.live(states, z))):
            term, value = element.law.stored(state, float(d[e]))
            strain += value if term == "strain" else 0.0
            contact += value if term == "contact" else 0.0
        return self.kinetic(z), strain, contact

    def stated(self, events: int) -> float:
        """The run's stated accuracy: rounding over its output steps and events, grown by its fastest mode's step."""
        from smdcli.solvers.base import stated_rounding

        grid = self.grid
        growth = max((flow.omega for flow in self.flows.values()), default=0.0)
        h = float(grid[-1] - grid[0]) / max(len(grid) - 1, 1) if len(grid) > 1 else 0.0
        return stated_rounding(len(grid) + 8 * events, max(1.0, growth * h))

    # ------------------------------------------------------------------------------------- energy
    def kinetic(self, z: np.ndarray) -> float:
        """1/2 v^T M v."""
        v = z[self.n:2 * self.n]
        return 0.5 * float(v @ self.model.M @ v)

    def integrate(self, flow: Flow, mode: Mode, states, z: np.ndarray, h: float, keep: bool) -> None:
        """The energy dissipated and put in over [0, h] of the flow from z (Gauss-Legendre)."""
        if h <= 0:
            return
        for term, gained in step_integrals(self, flow, mode, states, z[None], h, keep).items():
            self.cumulative[term] += float(gained[0])


def solve_piecewise(model: Model, grid: np.ndarray):
    """(x, v, a, history, description, stated accuracy) of an exact event-driven run; PiecewiseFailed where the
    scene cannot be advanced."""
    start = time.perf_counter()
    run = PiecewiseRun(model, grid)
    x, v, a, history = run.run()
    stated = run.stated(len(history.events))
    counts = {}
    for _, _, kind in history.events:
        counts[kind] = counts.get(kind, 0) + 1
    told = ", ".join(f"{count} {kind}" for kind, count in counts.items()) or "no events"
    message = (f"ok: event to event, {len(history.events)} events ({told}), {len(run.flows)} modes, "
               f"{time.perf_counter() - start:.3g} s")
    return x, v, a, history, message, stated


def solve_exactly(name: str, model: Model, grid: np.ndarray) -> Result:
    """A piecewise-linear scene solved by the exact method `name`, event to event; a scene it cannot advance is a
    failed run."""
    start = time.perf_counter()
    held_model, held = first_order_hold(model, grid)
    try:
        x, v, a, history, message, stated = solve_piecewise(held_model, grid)
    except PiecewiseFailed as exc:
        stats = SolverStats(method=name, requested_method=name, reason="", success=False,
                            message=f"failed: {exc}", wall_time_s=time.perf_counter() - start)
        nan = np.full((len(grid), model.n), np.nan)
        return make_result(held_model, grid, nan, nan, stats, t_failed=float(grid[0]))
    reason = ""
    if held and len(grid) > 1:
        fine = halved(grid)
        try:
            stated = max(stated, hold_error(model, grid, held), hold_response_error(
                x, lambda: solve_piecewise(first_order_hold(model, fine)[0], fine)[0]))
        except PiecewiseFailed:
            stated = max(stated, hold_error(model, grid, held))
        message += f"; first-order hold on the output grid for {', '.join(held)} (error O(step^2))"
        reason = held_reason(model, stated)
    stats = SolverStats(method=name, requested_method=name, reason=reason, nlu=0,
                        steps_accepted=max(len(grid) - 1, 0), wall_time_s=time.perf_counter() - start,
                        message=message, stated_accuracy=stated)
    return make_result(held_model, grid, x, v, stats, acceleration=a, nonsmooth=history)
