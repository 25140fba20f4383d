"""Integrators on scenes with nonsmooth elements: each mode integrated as the smooth system it is, every event
located on the method's own interpolant and the method restarted there.

A scene that is not linear between events (Bouc-Wen springs, velocity-weakening or regularized friction, stops and
friction beside cubic springs or quadratic dampers) is integrated mode by mode, with the same modes, guards and
decisions as the exact event-driven solver (scene.py, decisions.py): its state y = [x, v, q] (smooth_scene.py)
carries the laws' internal variables q (Bouc-Wen's z) with their differential equations. After every accepted
step each guard is looked at on the step's dense output (its ends and four interior points, so that a touch
within a step is seen), a crossing located by Brent's method on that interpolant, the step cut back there, the
event decided, and the method started afresh from the event. The energy terms' powers are integrated with the motion, under the
method's own error control.

Every method of the ODE family takes part (those with the registry's `events`). smd's compiled ones (with its
`compiled_modes`) run each mode in a compiled kernel (compiled_modes.py), guards watched and events located there,
Python back only at an event; scipy's OdeSolvers (scipy:RK45 ..., LSODA) are stepped from Python, a step at a
time, with the same modes and decisions: the compiled kernels' cross-check.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import time

import numpy as np

from smdcli.elements.base import KINK
from smdcli.kernels.arrays import INTERIOR
from smdcli.model import Model
from smdcli.model.nonsmooth import whole_tension
from smdcli.result import NonsmoothHistory, Result, SolverStats
from smdcli.solvers.base import MAX_STEPS, Tolerances, divergence_bound, diverged, force_function, make_result
from smdcli.solvers.events.compiled_modes import ACCUMULATED, CompiledModes, compiled_modes
from smdcli.solvers.events.scene import at_level, event_root
from smdcli.solvers.events.piecewise import PiecewiseRun, Pileup
from smdcli.solvers.events.record import stored_energies
from smdcli.solvers.events.smooth_scene import SmoothScene
from smdcli.solvers.registry import BY_NAME, OWN_SOLVERS

PYTHON_STEPS = 200_000  # steps a run may take, driven from Python (about 300 us each)


def ode_solver_class(name: str):
    """The OdeSolver class that integrates a method's modes (the registry's events: scipy's, or smd's own)."""
    formula = BY_NAME[name].events
    if formula in OWN_SOLVERS:
        from smdcli.solvers.integrators import stiff23

        return getattr(stiff23, formula)
    import scipy.integrate as si

    return getattr(si, formula)


class EventDriver(PiecewiseRun):
    """An OdeSolver, mode by mode, events located on its interpolant."""

    scene_class = SmoothScene

    def __init__(self, model: Model, grid: np.ndarray, tol: Tolerances, name: str):
        super().__init__(model, grid)
        self.tol, self.name = tol, name
        self.kernel_method = compiled_modes(name)  # None: an OdeSolver stepped from Python
        self.cls = ode_solver_class(name) if self.kernel_method is None else None
        self.own = BY_NAME[name].events in OWN_SOLVERS  # smd's: they take a Jacobian
        self.counts = {"nfev": 0, "njev": 0, "nlu": 0, "steps_accepted": 0, "steps_rejected": -1}
        self.max_steps = tol.max_steps or (PYTHON_STEPS if self.kernel_method is None else MAX_STEPS)
        self.fired = None  # (time, element, guard) of the last event
        # the time at which kinks of smooth laws fired one after another (a Bouc-Wen spring at rest: d' and z both 0,
        # each kink left at once): every guard crossing there is one left, not an event (compiled_modes.advance)
        self.kinks_left = None
        self.fastest_force = None  # rad/s, once asked (held_spacing)

    def run(self):
        """x, v, a (N, n), the history, and why it stopped (None: it reached the end) with where."""
        scene, grid, model = self.scene, self.grid, self.model
        y = np.concatenate([model.x0, model.v0, np.zeros(scene.q_size), np.zeros(len(ACCUMULATED))])
        for element, part in zip(scene.elements, scene.q_slices):
            start = element.law.start(0.0, 0.0)
            y[part] = [start.internal[name] for name in element.law.ode_states]
        t = float(grid[0])
        cuts = self.cut_times()
        scene.force = self.force_on(cuts, 0)
        scene.now = t
        states = [e.law.start(float(e.row @ model.x0), float(e.row @ model.v0 + e.belt)) for e in scene.elements]
        states, y = self.start(states, y, t)
        outputs = _Outputs(self, grid)
        outputs.store(0, t, y, states)
        self.bound = divergence_bound(model, grid)
        if self.kernel_method is not None:
            self.compiled = CompiledModes(self, len(y))
        k, segment = 1, 0
        failure, t_reached = None, t
        pileup = Pileup(float(grid[-1] - grid[0]) / max(len(grid) - 1, 1))
        while k < len(grid) and failure is None:
            while segment + 1 < len(cuts) and cuts[segment + 1][0] <= t:
                segment += 1
            scene.force = self.force_on(cuts, segment)
            advance = self.compiled.advance if self.kernel_method is not None else self.advance
            y, t_reached, event, failure, k = advance(states, t, y, cuts, segment, k, outputs)
            if failure:
                break
            if event is not None and event[2].kind == "slip" and segment + 1 < len(cuts) \
                    and event[0] == cuts[segment + 1][0]:
                # a stuck contact's force reaches its breakaway just where the force has a kink or a jump: whether
                # it slips is decided with the right limits (the force may turn back there), as exact decides it
                event = None
            if event is not None:
                t_event, element, guard = event
                if guard.kind == KINK and self.fired is not None and self.fired[0] == t_event and \
                        self.fired[2].kind == KINK:
                    self.kinks_left = t_event  # a second kink at one instant: each only left there
                self.fired = event
                failure = pileup.add(t_event, self.events)
                if failure:
                    break
                t = t_event
                scene.now = t
                states, y = self.apply(states, y, t, element, guard.kind)
                while k < len(grid) and grid[k] <= t:
                    outputs.store(k, float(grid[k]), y, states)
                    k += 1
                continue
            t = t_reached  # a restart (a force's discontinuity, the ground's jump) or the end
            while segment + 1 < len(cuts) and cuts[segment + 1][0] < t:
                segment += 1
            if segment + 1 < len(cuts) and t == cuts[segment + 1][0]:
                jump = cuts[segment + 1][1]
                scene.now = t
                scene.force = self.force_on(cuts, segment + 1)  # right limits: the modes are decided after the jump
                states, y = self.cross_break(states, y, t, jump)
                if k < len(grid) and grid[k] == t:
                    outputs.store(k, t, y, states)
                    k += 1
                elif jump is not None and k > 0 and grid[k - 1] == t:
                    outputs.store(k - 1, t, y, states)  # stored on the way as the left limit: a jump's sample is
                    # its right limit, as the exact solver and across_jumps give it
        self.sort_events()
        return outputs.finish(), failure, t_reached

    # ----------------------------------------------------------------------------------- the steps
    def advance(self, states, t: float, y: np.ndarray, cuts, segment: int, k: int, outputs):
        """The mode integrated by the OdeSolver from (t, y) to the segment's end or its first event, the grid's rows
        stored on the way: (y, time reached, the event (t, element, guard) or None, why it failed or None, next row)."""
        n, grid, bound = self.n, self.grid, self.bound
        t_end = cuts[segment + 1][0] if segment + 1 < len(cuts) else float(grid[-1])
        fun = self.rhs(states)
        options = {"jac": _numeric_jacobian(fun)} if self.own else {}
        spacing = self.held_spacing(self.scene.mode(states))
        options.update({"max_step": spacing} if spacing else {})
        solver = self.cls(fun, t, y, t_end, rtol=self.tol.rtol, atol=self.tol.atol, **options)
        event = failure = None
        t_reached = t
        while solver.status == "running":
            t_old = solver.t
            message = solver.step()
            if solver.status == "failed":
                failure = message or "step failed"
                break
            self.counts["steps_accepted"] += 1
            if self.counts["steps_accepted"] > self.max_steps:
                failure = f"more than {self.max_steps} steps"
                break
            dense = solver.dense_output()
            event = self.first_crossing_on(dense, states, t_old, solver.t)
            t_stop = solver.t if event is None else event[0]
            while k < len(grid) and grid[k] <= t_stop and (event is None or grid[k] < t_stop):
                outputs.store(k, float(grid[k]), dense(grid[k]), states)
                k += 1
            t_reached = t_stop
            failure = diverged(dense(t_stop)[:2 * n], bound)
            if event is not None or failure:
                y = dense(t_stop)
                break
            y = solver.y
        self.counts["nfev"] += solver.nfev
        self.counts["njev"] += solver.njev
        self.counts["nlu"] += solver.nlu
        return y, t_reached, event, failure, k

    def held_spacing(self, mode) -> float | None:
        """Where every mass is held (a mass at rest on its stop), the longest step that still sees the forces on
        what holds it change: a sixteenth of the fastest force's period. None elsewhere: the motion bounds the
        steps, where here nothing moves and a step would span periods, its samples missing the separation."""
        if mode.hold is None or np.linalg.matrix_rank(mode.hold[2]) < self.n:
            return None
        if self.fastest_force is None:
            omegas = [float(np.abs(np.linalg.eigvals(exo.S).imag).max()) for exo in self.scene.exos
                      if exo is not None and exo.S.size]
            self.fastest_force = max(omegas, default=0.0)
        return 2 * np.pi / self.fastest_force / 16 if self.fastest_force > 0 else None

    def speed_resolution(self) -> float:
        """The speed below which the method cannot tell a motion from rest: its tolerance on the run's speeds."""
        return max(super().speed_resolution(), self.tol.rtol * self.v_scale + self.tol.atol)

    def cut_times(self) -> list[tuple[float, object]]:
        """Where the method restarts: the start, force discontinuities, the ground's jumps, the end."""
        t0, t1 = float(self.grid[0]), float(self.grid[-1])
        inner = self.breaks()
        return [(t0, None)] + [(t, jump) for t, jump in inner if t < t1] + [(t1, None)]

    def force_on(self, cuts, segment: int):
        """u(t) on a segment: left limits at its end, as the method must not see the next jump."""
        ta = cuts[segment][0]
        tb = cuts[segment + 1][0] if segment + 1 < len(cuts) else ta
        return force_function(self.model, ta, tb) if self.model.is_forced else (lambda t: np.empty(0))

    def rhs(self, states):
        """y' in a mode: the motion, the laws' internal variables, and the energy terms' powers (integrated with the
        motion, so that the method's own error control holds the balance to its tolerance)."""
        n, scene = self.n, self.scene

        def fun(t, y):
            accel, tension, qdot = scene.parts(states, t, y)
            return np.concatenate([y[n:2 * n], accel, qdot, self.powers(states, t, y, tension)])

        return fun

    def powers(self, states, t: float, y: np.ndarray, tension: np.ndarray) -> np.ndarray:
        """The rates of ACCUMULATED at (t, y): what the dampers and the elements dissipate, what is put in."""
        scene, n, model = self.scene, self.n, self.model
        x, v = y[:n], y[n:2 * n]
        out = np.zeros(len(ACCUMULATED))
        out[0] = float(v @ model.C @ v) + _quadratic_power(model, v)
        out[1] = float(tension @ scene.belts)  # a belt's work on its contacts
        if model.signals:
            out[1] += float((model.B @ scene.force(t)) @ v)
        d, rate = scene.R @ x, scene.R @ v + scene.belts
        for e, (element, state) in enumerate(zip(scene.elements, scene.live(states, y))):
            term, power = element.law.dissipation(state, float(d[e]), float(rate[e]), float(tension[e]))
            if term:
                out[ACCUMULATED.index(term)] += power
        return out

    def first_crossing_on(self, dense, states, t0: float, t1: float):
        """(t, element, guard) of the earliest guard crossing in (t0, t1] on the step's interpolant, or None."""
        scene = self.scene
        guards = [(e, guard) for e, (el, s) in enumerate(zip(scene.elements, states)) for guard in el.law.piece(s).guards]
        if not guards:
            return None
        times = np.linspace(t0, t1, INTERIOR + 2)
        values = np.array([self.guard_values(guards, states, t, dense(t)) for t in times])
        best = None
        for j, (e, guard) in enumerate(guards):
            s = guard.direction

            def value(t, j=j):
                return self.guard_values(guards, states, t, dense(t))[j]

            def fired_again(root, e=e, guard=guard):  # the guard that just fired, read on the far side of its rounding
                return self.fired is not None and (self.fired[1:] == (e, guard) or self.kinks_left == self.fired[0]) \
                    and root - self.fired[0] <= 16 * np.spacing(max(abs(self.fired[0]), 1e-300))

            root = None
            for i in range(len(times) - 1):
                if s * values[i, j] < 0 <= s * values[i + 1, j]:
                    lo, hi = times[i], times[i + 1]
                    root = hi if value(hi) == 0 else event_root(value, lo, hi, hi - lo)
                    if fired_again(root):
                        root = None
                        continue
                    break
            slope = (values[1, j] - values[0, j]) / (times[1] - times[0])  # for the rounding of the time it started
            at = at_level(abs(values[0, j] + guard.level), guard.level) + abs(slope) * 16 * np.spacing(abs(t0))
            if root is None and abs(values[0, j]) <= at and s * values[1, j] >= 0:
                # a kink's dip deeper than the interpolant's rounding over the step (kernels.guards.first_crossing's)
                noise = max(at_level(abs(f + guard.level), guard.level) for f in values[:, j]) if guard.kind == KINK \
                    else 0.0
                root = _return(value, s, guard.level, t0, times[1], values[1, j], noise)
                root = None if root is None or fired_again(root) else root
            if root is not None and (best is None or root < best[0]):
                best = (root, e, guard)
        return best

    def guard_values(self, guards, states, t: float, y: np.ndarray) -> np.ndarray:
        """Each guard's quantity less its level at (t, y)."""
        self.scene.now = t
        d, rate, tension, _ = self.scene.evaluate(states, y)
        table = {"d": d, "rate": rate, "tension": tension}
        live = None
        values = []
        for e, g in guards:
            if g.quantity.startswith("internal:"):
                live = live or self.scene.live(states, y)
                values.append(live[e].internal[g.quantity.split(":", 1)[1]] - g.level)
            else:
                values.append(table[g.quantity][e] - g.level)
        return np.array(values)

class RecordedRun(EventDriver):
    """The event-driven run with each restart kept in `restarts`: (t, element, guard or None, kind, the modes and y
    before, after), an event's or a force's break ("break"); `first`: the modes and y after the start's decisions,
    `struck_at_start`: whether a stop was met moving into it there (what sensitivities carried over it read)."""

    def __init__(self, model: Model, grid: np.ndarray, tol: Tolerances, name: str):
        super().__init__(model, grid, tol, name)
        self.restarts: list[tuple] = []
        self.first, self.struck_at_start = None, False

    def start(self, states, y, t):
        before = len(self.events)
        states, y = super().start(states, y, t)
        self.first = (list(states), y.copy())
        self.struck_at_start = any(kind == "impact" for _, _, kind in self.events[before:])
        return states, y

    def apply(self, states, y, t, element, kind):
        after, y_after = super().apply(states, y, t, element, kind)
        self.restarts.append((t, element, self.fired[2], kind, list(states), y.copy(), list(after), y_after.copy()))
        return after, y_after

    def cross_break(self, states, y, t, jump):
        after, y_after = super().cross_break(states, y, t, jump)
        self.restarts.append((t, None, None, "break", list(states), y.copy(), list(after), y_after.copy()))
        return after, y_after


def _return(value, s: float, level: float, t0: float, hi: float, f_hi: float, noise: float = 0.0) -> float | None:
    """Where a guard at its level at t0 and past it again at hi comes back to it after a dip below it (deeper than
    noise) too short for the samples to see (a light rebound landing again): the dip found by halving towards t0,
    then the crossing located; t0 where it went on past its level instead, None where it only stays at it to
    rounding (as smdcli.kernels.guards._return)."""
    tau = hi - t0
    for _ in range(60):
        tau *= 0.5
        f = value(t0 + tau)
        if s * f < -noise:
            return hi if f_hi == 0 else event_root(value, t0 + tau, hi, hi - t0 - tau)
    return t0 if s * f_hi > at_level(abs(f_hi + level), level) else None


def _numeric_jacobian(fun):
    """A forward-difference Jacobian of fun(t, y), for the methods that ask for one."""
    def jac(t, y):
        f0 = fun(t, y)
        J = np.empty((len(y), len(y)))
        for j in range(len(y)):
            h = 1.5e-8 * max(abs(y[j]), 1e-8)
            step = y.copy()
            step[j] += h
            J[:, j] = (fun(t, step) - f0) / h
        return J

    return jac


def _quadratic_power(model: Model, v: np.ndarray) -> float:
    """What the quadratic dampers dissipate at v: the sum of c |d'| d'^2."""
    q = model.quadratic
    if q is None:
        return 0.0
    rate = q.D @ v
    return float((q.coef * np.abs(rate) * rate * rate).sum())


class _Outputs:
    """What an integrator run records at each output point."""

    def __init__(self, run: EventDriver, grid: np.ndarray):
        self.run = run
        N, n, E = len(grid), run.n, run.scene.E
        self.x, self.v, self.a = np.full((N, n), np.nan), np.full((N, n), np.nan), np.full((N, n), np.nan)
        self.tension = np.full((N, E), np.nan)
        self.internal = {f"{el.path}.{name}": np.full(N, np.nan) for el in run.scene.elements
                         for name in el.law.internal_names}
        self.energy = {name: np.full(N, np.nan) for name in run.energy_terms + ("kinetic", "strain", "contact")}

    def store(self, k: int, t: float, y: np.ndarray, states) -> None:
        """Row k at (t, y): the right-hand side's acceleration and tensions at it."""
        self.run.scene.now = t
        accel, tension, _ = self.run.scene.parts(states, t, y)
        self.store_rows(k, k + 1, y[None], accel[None], tension[None], states)

    def store_rows(self, k0: int, k1: int, Y: np.ndarray, A: np.ndarray, T: np.ndarray, states) -> None:
        """Rows k0..k1-1 at once, from the states Y, accelerations A and the elements' own tensions T (a compiled
        kernel's rows, or one row of the Python-driven methods)."""
        if k1 <= k0:
            return
        run = self.run
        scene, n = run.scene, run.n
        x, v = Y[:, :n], Y[:, n:2 * n]
        self.x[k0:k1], self.v[k0:k1], self.a[k0:k1] = x, v, A
        run.v_scale = max(run.v_scale, float(np.abs(v).max(initial=0.0)))
        d = x @ scene.R.T
        self.tension[k0:k1] = whole_tension(scene.elements, T, d)
        for e, (element, state) in enumerate(zip(scene.elements, scene.live(states, Y))):
            law = element.law
            for name, value in zip(law.internal_names, law.internal_values(state, d[:, e])):
                self.internal[f"{element.path}.{name}"][k0:k1] = value
        self.energy["kinetic"][k0:k1], self.energy["strain"][k0:k1], self.energy["contact"][k0:k1] = \
            stored_energies(run, states, Y)
        first = Y.shape[1] - len(ACCUMULATED)
        for name in run.energy_terms:
            self.energy[name][k0:k1] = run.cumulative[name] + Y[:, first + ACCUMULATED.index(name)]

    def finish(self):
        run = self.run
        paths = tuple(e.path for e in run.scene.elements)
        kinds = tuple(e.kind for e in run.scene.elements)
        energy = dict(self.energy, quadrature="the powers integrated with the motion under the method's own error "
                                             "control, restarted at events")
        return self.x, self.v, self.a, NonsmoothHistory(paths, kinds, self.tension, self.internal,
                                                         tuple(run.events), energy, **run.event_arrays())


def load_method(name: str) -> None:
    """The compiled kernel that runs a method's modes loaded (from numba's cache), or its OdeSolver imported: before
    any clock starts."""
    kernel = compiled_modes(name)
    if kernel is not None:
        from smdcli.solvers.integrators.compiled import warm

        warm(f"modes:{kernel[0]}")
    else:
        ode_solver_class(name)


def solve_events(model: Model, grid: np.ndarray, tol: Tolerances, name: str) -> Result:
    """A nonsmooth scene integrated by method `name` (one with the registry's events), event to event."""
    kernel = compiled_modes(name)
    load_method(name)
    start = time.perf_counter()
    driver = EventDriver(model, grid, tol, name)
    (x, v, a, history), failure, t_reached = driver.run()
    events = len(history.events)
    stats = SolverStats(method=name, requested_method=name, reason="", rtol=tol.rtol, atol=tol.atol,
                        wall_time_s=time.perf_counter() - start, success=failure is None,
                        message=(f"ok: {events} events located on the method's interpolant, a restart at each"
                                 + (" (compiled)" if kernel is not None else "")
                                 if failure is None else f"failed at t = {t_reached:.6g} s: {failure}"),
                        **driver.counts)
    return make_result(model, grid, x, v, stats, t_failed=None if failure is None else t_reached, acceleration=a,
                       nonsmooth=history)
