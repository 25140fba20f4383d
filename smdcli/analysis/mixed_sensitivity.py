"""Sensitivities of scenes that mix events with smooth nonlinear terms: velocity-weakening (Stribeck) friction, and
Coulomb friction or stops beside Bouc-Wen springs, cubic springs or quadratic dampers.

The scene is run first by the event-driven integrator (integrated.py, compiled DOP853 at the sensitivities'
tolerance), which records every restart: each event's time, element, guard and the modes and state on either side,
each force discontinuity. Between two restarts the mode is a smooth system y' = f(t, y), y = [x, v, q], whose
sensitivities s = dy/dp obey s' = J s + df/dp: integrated beside the state by smooth_sensitivity's compiled kernel
on the mode's arrays (J analytic, a Bouc-Wen law's kinks crossed there), error controlled on both, df/dp from the
scene at the parameter's stencil points (model_derivative), never a difference of solutions; or, the tests' second
way, by scipy's DOP853 from Python with J s a central difference of f along s. At an event of p-dependent time
t*, where a guard g(t, y, p) crosses its level, dt*/dp = -(dg/dy s + dg/dp) / (dg/dt along the flow), and the
sensitivity jumps (the saltation): s+ = D[Delta](s- + f- dt*/dp) - f+ dt*/dp, with Delta the identity for a change
of mode and the velocity jump of an impact (its derivative taken at the scene's stencil points along the moved event
point). A kink of a smooth law leaves f continuous, so s too. Where a guard's top comes within GRAZE of its level
without crossing it, the response has no derivative from there: nan, and the reason.

Laws whose events set internal variables of their own (a yielding spring's plastic deformation, a Clough spring's
target) carry their sensitivities as the exact event runs do (event_sensitivity.py): set at each event by the law's
own event at the moved point, read by the modes after it at the stencil's points (shifted_states).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.analysis.event_edges import breakaway_margins, continuous, on_breakaway, shifted_states
from smdcli.analysis.mixed_edges import MixedEdges
from smdcli.analysis.signal_derivative import shifted_stencil_total, stencil_total
from smdcli.elements.base import KINK
from smdcli.errors import SolverFailed
from smdcli.model import Model
from smdcli.solvers.base import Tolerances, force_function
from smdcli.solvers.events.decisions import impact, project
from smdcli.solvers.events.integrated import RecordedRun
from smdcli.solvers.events.smooth_scene import SmoothScene

METHOD = ("forward sensitivity equations s' = J s + df/dp integrated beside the state by {how} from event to event "
          "(error controlled on both; df/dp from the model at the parameter's stencil points), each event's time "
          "derivative from its guard and the sensitivities' jump across it (saltation)")
RECORDED_BY = "DOP853"  # the method of the event-driven run the sensitivities are carried over (compiled modes)
ALONG = 2.0 ** -17  # J s as a central difference of f over this share of the state's size along s
GRAZING = 1e-9  # a crossing whose rate is below this share of the terms it sums is met tangentially: no dt*/dp




class MixedRun(MixedEdges):
    """The sensitivities of a mixed scene carried over a recorded run: scale_i dy/dp_i, each block the state's size."""

    def __init__(self, model: Model, derivatives: list, scales: np.ndarray, grid: np.ndarray, rtol: float):
        self.model, self.grid, self.rtol, self.scales = model, grid, rtol, scales
        self.P = len(derivatives)
        self.scene = SmoothScene(model)
        self.n, self.m = model.n, 2 * model.n + self.scene.q_size
        self.stencils = [([self.scene if m is model else SmoothScene(m) for m in d.models],
                          np.asarray(d.offsets, dtype=float) * d.delta, d.weights * scale)
                         for d, scale in zip(derivatives, scales)]
        self.undefined_from: tuple[float, str] | None = None
        self.edges: dict[int, str] = {}
        self.events: list = []
        self.peak_points: list[tuple] = []  # (t, x, scale_i dx/dp_i along the moved event) at each event: peaks there
        self._kept: dict = {}  # the kernels' arrays of each scene and mode
        self.implicit = False  # whether a piece was stiff: Radau's kernel took it
        # each element's internal numbers that its events set (not integrated: a plastic deformation) -> their (P,)
        # scaled sensitivities, as they stand; and as they stood over each piece of the run
        self.dq: list[dict] = [{} for _ in self.scene.elements]
        self.piece_dq: list[list[dict]] = []

    def total(self, i: int, read) -> np.ndarray:
        """scale_i times the total derivative along parameter i of read(scene, c) (stencil_total)."""
        return stencil_total(self.stencils[i], self.scales[i], read)

    def shifted_total(self, i: int, read) -> np.ndarray:
        """total of a read at the state moved with the parameter at every point (shifted_stencil_total)."""
        return shifted_stencil_total(self.stencils[i], self.scales[i], read)

    def no_derivative(self, t: float, why: str) -> None:
        """From t on the response has no derivative: nan from here, the reason kept."""
        if self.undefined_from is None or t < self.undefined_from[0]:
            self.undefined_from = (t, why)

    # ----------------------------------------------------------------------------- the flow
    def _rate(self, scene: SmoothScene, states, t: float, y: np.ndarray) -> np.ndarray:
        accel, _, qdot = scene.parts(states, t, y)
        return np.concatenate([y[self.n:2 * self.n], accel, qdot])

    def _rates(self, states, t: float, y: np.ndarray, S: np.ndarray, dq=None) -> tuple[np.ndarray, np.ndarray]:
        """(y', S') at (t, y, S) in these modes: S' = J S + df/dp, column by column, df/dp with the internal numbers'
        sensitivities dq (the run's current ones by default)."""
        dq = self.dq if dq is None else dq
        f = self._rate(self.scene, states, t, y)
        size = float(np.abs(y).max(initial=0.0))
        out = np.empty_like(S)
        for i in range(self.P):
            s = S[:, i]
            length = float(np.abs(s).max(initial=0.0))
            if length > 0:
                eps = ALONG * max(size, 1e-300) / length
                ahead, back = (self._rate(self.scene, states, t, y + side * eps * s) for side in (1.0, -1.0))
                along = (ahead - back) / (2 * eps)
            else:
                along = 0.0
            out[:, i] = along + self.total(i, lambda scene, c, i=i: f if scene is self.scene else
                                           self._rate(scene, shifted_states(states, dq, i, c), t, y))
        return f, out

    # ----------------------------------------------------------------------------- the run
    def run(self, tol: Tolerances, advance=None):
        """(y, S, y', S') on the grid ((N, m), (N, m, P), (N, m), (N, m, P)) and rates_at(t, left)."""
        recorded = RecordedRun(self.model, self.grid, tol, RECORDED_BY)
        (x, v, _, history), failure, t_reached = recorded.run()
        if failure:
            raise SolverFailed(f"{self.model.source}: the scene could not be run for its sensitivities: failed at "
                               f"t = {t_reached:.6g} s: {failure}")
        self.events, self.v_scale = recorded.events, recorded.v_scale
        if recorded.struck_at_start:
            self.no_derivative(float(self.grid[0]), "a stop is met moving into it at the start")
        self.atol = self._absolute(x, v, history)
        self.cuts = [t for t, _ in recorded.cut_times()]
        grid, m, P = self.grid, self.m, self.P
        N = len(grid)
        Y, dY = np.full((N, m * (1 + P)), np.nan), np.full((N, m * (1 + P)), np.nan)
        self.row_piece = np.zeros(N, dtype=int)  # the piece each output row was read in
        states, y = recorded.first
        y, t = y[:m], float(grid[0])
        self._on_cut(t)
        S = self._initial()
        self.pieces, filled = [], 0
        end_mark = (float(grid[-1]), None, None, "end", None, None, None, None)
        for t_next, element, guard, kind, before, y_before, after, y_after in [*recorded.restarts, end_mark]:
            self._on_cut(t)
            last = kind == "end"
            rest = grid[filled:]
            wanted = rest[(rest < t_next) | (last & (rest <= t_next))]
            times = np.unique(np.concatenate([[t], wanted, [t_next]]))
            rows, rates = self._piece(states, times, np.concatenate([y, S.ravel()]))
            self.pieces.append((t, t_next, list(states), times, rows, rates))
            self.piece_dq.append([{k: v.copy() for k, v in d.items()} for d in self.dq])
            at = np.searchsorted(times, wanted)
            Y[filled:filled + len(wanted)], dY[filled:filled + len(wanted)] = rows[at], rates[at]
            self.row_piece[filled:filled + len(wanted)] = len(self.pieces) - 1
            filled += len(wanted)
            if advance is not None and len(wanted):
                advance(len(wanted))
            if t_next > t:
                self._near_miss(len(self.pieces) - 1, (element, guard))
            if last:
                break
            S = self._jump(t_next, element, guard, kind, before, y_before[:m], after, y_after[:m],
                           rows[-1, m:].reshape(m, P))
            states, y, t = after, y_after[:m], t_next
        if filled != N:
            raise SolverFailed(f"{self.model.source}: the sensitivity equations filled {filled} of {N} output times")
        return self._outputs(Y, dY)

    def _piece(self, states, times: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """[y; S] and its rate at each of times (from start at times[0], in these modes): by the compiled kernel
        (smooth_sensitivity's, on the mode's arrays) or by scipy's DOP853 from Python (the tests' second way)."""
        from smdcli.analysis.smooth_sensitivity import COMPILED

        if len(times) == 1:
            return start[None], self._augmented(states, float(times[0]), start)[None]
        if COMPILED:
            return self._compiled(states, times, start)
        from scipy.integrate import solve_ivp

        run = solve_ivp(lambda tt, Z: self._augmented(states, tt, Z), (times[0], times[-1]), start, method="DOP853",
                        rtol=self.rtol, atol=self.atol, t_eval=times)
        if run.status < 0:
            raise SolverFailed(f"{self.model.source}: the sensitivity equations failed at t = "
                               f"{run.t[-1] if len(run.t) else times[0]:.6g} s: {run.message}")
        rows = np.asarray(run.y).T
        return rows, np.array([self._augmented(states, float(t), row) for t, row in zip(times, rows)])

    def _compiled(self, states, times: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """_piece by the compiled kernel (smooth_sensitivity.grouped_runs) on the mode's arrays of the scene and of
        each stencil point's scene."""
        from smdcli.analysis.smooth_sensitivity import grouped_runs, mass_ratio

        m, P, N = self.m, self.P, len(times)
        base = self._arrays(self.scene, states)
        stencil = [(i, w, self._arrays(scene, shifted_states(states, self.dq, i, o / self.scales[i])),
                    mass_ratio(self.model, scene.model))
                   for i, (scenes, offsets, weights) in enumerate(self.stencils)
                   for w, scene, o in zip(weights, scenes, offsets) if scene is not self.scene]
        state0 = np.concatenate([start[:m], np.zeros(base.ns_acc)])
        y, S, rate, d_S, implicit = grouped_runs(base, stencil, state0, start[m:].reshape(m, P), times,
                                       np.array([times[0], times[-1]]), self.rtol, self.atol, self.model.source)
        self.implicit = self.implicit or implicit
        return np.hstack([y, S.reshape(N, m * P)]), np.hstack([rate, d_S.reshape(N, m * P)])

    def _arrays(self, scene: SmoothScene, states):
        """The kernels' arrays of a scene's mode in these states (kept by the mode)."""
        from smdcli.solvers.events.compiled_modes import mode_arrays, scene_arrays

        mode = scene.mode(states)
        key = (id(scene), id(mode))
        if key not in self._kept:
            if id(scene) not in self._kept:
                self._kept[id(scene)] = scene_arrays(scene)
            self._kept[key] = mode_arrays(self._kept[id(scene)], scene, mode, states)
        return self._kept[key]

    def _on_cut(self, t: float) -> None:
        """Every scene's forces on the force segment that holds t (left limits at its end)."""
        cuts = self.cuts
        cut = max(int(np.searchsorted(cuts, t, side="right")) - 1, 0)
        ta, tb = cuts[cut], cuts[min(cut + 1, len(cuts) - 1)]
        for scene in [self.scene, *(s for scenes, _, _ in self.stencils for s in scenes)]:
            scene.force = force_function(scene.model, ta, tb) if scene.model.is_forced else (lambda _: np.empty(0))

    def _augmented(self, states, t: float, Z: np.ndarray, dq=None) -> np.ndarray:
        m = self.m
        f, dS = self._rates(states, t, Z[:m], Z[m:].reshape(m, self.P), dq)
        return np.concatenate([f, dS.ravel()])

    def _absolute(self, x: np.ndarray, v: np.ndarray, history) -> np.ndarray:
        """Absolute tolerances of [y, S] from each component's peak over the recorded run (smooth_sensitivity's)."""
        from smdcli.analysis.smooth_sensitivity import absolute_tolerances

        peaks = [np.nanmax(np.abs(x), axis=0), np.nanmax(np.abs(v), axis=0)]
        for element in self.scene.elements:
            peaks += [np.array([np.nanmax(np.abs(history.internal[f"{element.path}.{name}"]), initial=0.0)])
                      for name in element.law.ode_states]
        return absolute_tolerances(np.concatenate(peaks), self.P, self.rtol)

    def _initial(self) -> np.ndarray:
        """S at the start: each parameter's derivative of [x0, v0, q0]; a start on the edge of two branches (its
        modes differ within the parameter's step, or a contact held at its breakaway force that the step moves off
        it) is carried as zeros and read as nan."""
        S = np.zeros((self.m, self.P))
        nominal = None
        scene = self.scene
        d0, rate0 = scene.R @ self.model.x0, scene.R @ self.model.v0 + scene.belts
        set_names = [list(self._set_numbers(e, el.law.start(float(d0[e]), float(rate0[e]))))
                     for e, el in enumerate(scene.elements)]  # the internal numbers the start sets, not integrated
        for i in range(self.P):
            branches, margins = set(), {}

            def initial(scene, c):
                model = scene.model
                d0, rate0 = scene.R @ model.x0, scene.R @ model.v0 + scene.belts
                starts = [el.law.start(float(d0[e]), float(rate0[e])) for e, el in enumerate(scene.elements)]
                branches.add(tuple(s.mode for s in starts))
                q0 = [s.internal[name] for el, s in zip(scene.elements, starts) for name in el.law.ode_states]
                y0 = np.concatenate([model.x0, model.v0, np.asarray(q0, dtype=float)])
                scene.now = float(self.grid[0])
                margins[c] = breakaway_margins(scene, starts, y0)
                numbers = [continuous(s.internal) for s in starts]
                return np.concatenate([y0, [numbers[e][name] for e, names in enumerate(set_names) for name in names]])
            column = self.total(i, initial)
            if nominal is None:
                initial(self.scene, 0.0)
                nominal = margins.pop(0.0)
            held = on_breakaway(margins, nominal, self.scene)
            if len(branches) > 1 or held:
                self.edges[i] = (f"{', '.join(held) or 'an element'} starts on the edge between two of its modes "
                                 "(within the parameter's step: a contact held at its breakaway force), where the "
                                 "response's derivatives on either side differ")
                column = np.zeros_like(column)
            S[:, i] = column[:self.m]
            at = iter(column[self.m:])
            for e, names in enumerate(set_names):
                for name in names:
                    self.dq[e].setdefault(name, np.zeros(self.P))[i] = next(at)
        return S

    # ----------------------------------------------------------------------------- events
    def _guard_value(self, scene: SmoothScene, states, t: float, y: np.ndarray, element: int, guard) -> float:
        """The guard's quantity less its level (the level as the scene at this stencil point has it)."""
        match = next(g for g in scene.elements[element].law.piece(states[element]).guards
                     if (g.kind, g.direction, g.quantity) == (guard.kind, guard.direction, guard.quantity))
        scene.now = t
        if match.quantity.startswith("internal:"):
            return float(scene.live(states, y)[element].internal[match.quantity.split(":", 1)[1]]) - match.level
        d, rate, tension, _ = scene.evaluate(states, y)
        return float({"d": d, "rate": rate, "tension": tension}[match.quantity][element]) - match.level

    def _jump(self, t: float, element, guard, kind: str, before, y_before: np.ndarray, after, y_after: np.ndarray,
              S: np.ndarray) -> np.ndarray:
        """S after a restart at t: continuous across a force's break and a smooth law's kink (f is); across an event
        of p-dependent time, the saltation."""
        if kind == "break" and any(abs(when - t) <= 1e-12 * max(abs(t), 1.0) for when, _, _ in self.model.jumps):
            return self._across_jump(t, before, y_before, after, S)
        if kind in ("break", KINK):
            return S
        if self.undefined_from is not None and self.undefined_from[0] <= t:
            self.peak_points.append((t, y_before[:self.n].copy(), np.full((self.P, self.n), np.nan)))
            return S
        scene, P = self.scene, self.P
        f_before = self._rate(scene, before, t, y_before)
        # the guard's rate along the flow: a five-point central difference along the motion's tangent, its time read
        # by the forces too (a held contact's force grows with them while nothing moves), over a ten-thousandth of
        # the output step
        tau = 1e-4 * float(self.grid[-1] - self.grid[0]) / max(len(self.grid) - 1, 1)
        at = {o: self._guard_value(scene, before, t + o * tau, y_before + o * tau * f_before, element, guard)
              for o in (-2, -1, 1, 2)}
        crossing = (8 * (at[1] - at[-1]) - (at[2] - at[-2])) / (12 * tau)
        terms = abs(at[1]) + abs(at[-1])
        dt = np.zeros(P)
        if abs(crossing) * 2 * tau <= GRAZING * max(terms, 1e-300) or crossing == 0:
            self.no_derivative(t, f"{scene.elements[element].path} meets its {kind} tangentially: a graze, whose "
                               "time has no derivative")
            self.peak_points.append((t, y_before[:self.n].copy(), np.full((P, self.n), np.nan)))
            return S
        for i in range(P):
            dt[i] = -float(self.shifted_total(i, lambda sc, c: self._guard_value(
                sc, shifted_states(before, self.dq, i, c), t, y_before + c * S[:, i], element, guard))) / crossing
        self.moves = getattr(self, "moves", {})
        self.moves.setdefault(t, dt)
        moved = S + f_before[:, None] * dt[None]  # the event point's total derivative
        self.peak_points.append((t, y_before[:self.n].copy(), moved[:self.n].T.copy()))
        if kind == "impact":
            n = self.n
            out = np.empty_like(moved)
            for i in range(P):
                def jumped(sc, c, i=i):
                    z = y_before + c * moved[:, i]
                    struck = impact(sc, shifted_states(before, self.dq, i, c), z[:2 * n], element,
                                    sc.elements[element].law.rebound)
                    return np.concatenate([project(sc, shifted_states(after, self.dq, i, c), struck, self.v_scale),
                                           z[2 * n:]])
                out[:, i] = self.shifted_total(i, jumped)
            moved = out
        self._carry_internal(t, element, kind, before, after, y_before, moved)
        f_after = self._rate(scene, after, t, y_after)
        return moved - f_after[:, None] * dt[None]

    def _carried(self, index: int, t: float) -> np.ndarray:
        """[y; S] at t inside piece `index`: from its last row at or before t, by scipy's DOP853."""
        from scipy.integrate import solve_ivp

        ta, tb, states, times, rows, _ = self.pieces[index]
        k = max(int(np.searchsorted(times, t, side="right")) - 1, 0)
        if t <= times[k]:
            return rows[k]
        self._on_cut(float(times[k]))
        dq = self.piece_dq[index]
        run = solve_ivp(lambda tt, Z: self._augmented(states, tt, Z, dq), (times[k], t), rows[k], method="DOP853",
                        rtol=self.rtol, atol=self.atol)
        return run.y[:, -1]

    # ----------------------------------------------------------------------------- outputs
    def _outputs(self, Y: np.ndarray, dY: np.ndarray):
        grid, m, P = self.grid, self.m, self.P
        y, S = Y[:, :m], Y[:, m:].reshape(len(grid), m, P)
        rates, d_rates = dY[:, :m], dY[:, m:].reshape(len(grid), m, P)
        if self.undefined_from is not None:
            later = grid >= self.undefined_from[0]
            S[later], d_rates[later] = np.nan, np.nan
        for i in self.edges:
            S[:, :, i], d_rates[:, :, i] = np.nan, np.nan
        self.grid_states = y, S
        starts = np.array([a for a, *_ in self.pieces])

        def rates_at(t: float, left: bool = False) -> tuple[np.ndarray, np.ndarray]:
            index = max(int(np.searchsorted(starts, t, side="left" if left else "right")) - 1, 0)
            Z = self._carried(index, t)
            f, dS = self._rates(self.pieces[index][2], t, Z[:m], Z[m:].reshape(m, P), self.piece_dq[index])
            if self.undefined_from is not None and t >= self.undefined_from[0]:
                dS = np.full_like(dS, np.nan)
            for i in self.edges:
                dS[:, i] = np.nan
            return f, dS
        rates_at.breaks = np.array([b for _, b, *_ in self.pieces[:-1]], dtype=float)
        return y, S, rates, d_rates, rates_at


def mixed_sensitivities(model: Model, derivatives: list, scales: np.ndarray, grid: np.ndarray, rtol: float,
                        atol: float, advance=None):
    """(y, dy/dp * scale, y', dy'/dp * scale) on the grid ((N, s), (N, s, P), (N, s), (N, s, P)), rates_at(t, left),
    the method's text and the run (its events, and where the derivatives stop existing) of a scene that mixes events
    with smooth nonlinear terms. The recorded run's absolute tolerance: atol, or a thousandth of rtol of the smaller
    of the state's peaks (displacement, velocity) where that is tighter, from a first run of the scene at rtol 1e-6
    (compiled)."""
    from smdcli.solvers.events.integrated import solve_events

    first = solve_events(model, grid, Tolerances(rtol=1e-6, atol=1e-12), RECORDED_BY)
    sizes = [float(np.nanmax(np.abs(a), initial=0.0)) for a in (first.displacement, first.velocity)]
    size = min((s for s in sizes if s > 0), default=1.0)
    run = MixedRun(model, derivatives, scales, grid, rtol)
    y, S, rates, d_rates, rates_at = run.run(Tolerances(rtol=rtol, atol=min(atol, 1e-3 * rtol * size)), advance)
    from smdcli.analysis.smooth_sensitivity import COMPILED

    how = "DOP853 in Python (J s a central difference along s)" if not COMPILED else \
        "compiled Radau IIA 5 where a piece is stiff, DOP853 elsewhere (J analytic)" if run.implicit else \
        "compiled DOP853 (J analytic)"
    return y, S, rates, d_rates, rates_at, METHOD.format(how=how), run
