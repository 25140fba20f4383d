"""MixedRun's edges (mixed_sensitivity.py): where a guard comes within rounding of its level without crossing it (a
graze: no derivative from there), and the internal numbers a law's events set (a plastic deformation), whose
sensitivities are carried from event to event as the exact event runs carry them.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.analysis.event_edges import GRAZE, across_ground_jump, carry_numbers, continuous, shifted_states
from smdcli.elements.base import KINK, RATE
from smdcli.model.nonsmooth import whole_tension

NEAR_LEVEL = 1e-2  # a guard's top that the rows' interpolant puts within this share of its size is looked at closely


class MixedEdges:
    """MixedRun's graze watch and its internal numbers' sensitivities."""

    def _near_miss(self, index: int, ending) -> None:
        """A guard whose top comes within GRAZE of its level inside piece `index` without crossing it (the guard that
        ends the piece aside): an event a change of the parameters this small makes appear, so no derivative from
        there. Looked at on the piece's rows; a top among them that the rows' cubic interpolant brings within
        NEAR_LEVEL of the level is found on the state carried there."""
        from scipy.interpolate import CubicHermiteSpline
        from scipy.optimize import minimize_scalar

        scene, m = self.scene, self.m
        ta, tb, states, times, rows, rates = self.pieces[index]
        cubic = CubicHermiteSpline(times, rows[:, :m], rates[:, :m]) if len(times) > 2 else None
        guards = [(e, g) for e, (el, s) in enumerate(zip(scene.elements, states)) for g in el.law.piece(s).guards
                  if g.kind != KINK and (e, g) != ending]
        # elements met at the piece's end by the event that ends it (a spring unloading where the mass stops, and the
        # friction contact on the same mass turning there): their guards reach their levels with it, no graze
        met = {path for when, path, _ in self.events if when == tb}
        for e, guard in guards:
            def below(t, y, e=e, guard=guard):  # how far below its level the guard is: > 0 until it crosses
                return -guard.direction * self._guard_value(scene, states, float(t), y, e, guard)
            values = np.array([below(t, row[:m]) for t, row in zip(times, rows)])
            # its lowest points: between rows (a plateau, the scene at rest, is none), and the piece's end where
            # another restart (a kink at the turn) ends it
            inner = (values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:]) & \
                ((values[1:-1] < values[:-2]) | (values[1:-1] < values[2:]))
            lows = [(j, True) for j in np.flatnonzero(inner) + 1]
            if scene.elements[e].path not in met:
                lows += [(len(values) - 1, False)] if len(values) > 1 and values[-1] < values[-2] else []
            for j, between in lows:
                when, top = float(times[j]), -float(values[j])
                size = self._guard_size(states, rows[j, :m], e, guard)
                if between:
                    bounds, tight = (times[j - 1], times[j + 1]), {"xatol": 1e-12 * max(abs(tb), 1.0)}
                    rough = minimize_scalar(lambda t: below(t, cubic(t)), bounds=bounds, method="bounded",
                                            options=tight)
                    if -float(rough.fun) < -NEAR_LEVEL * size:
                        continue  # far below its level: no graze, whatever the interpolant's error
                    found = minimize_scalar(lambda t: below(t, self._carried(index, float(t))[:m]), bounds=bounds,
                                            method="bounded", options=tight)
                    when, top = float(found.x), -float(found.fun)
                if -GRAZE * size <= top < 0:
                    self.no_derivative(when, f"{scene.elements[e].path} comes within {-top:.3g} of its "
                                       f"{guard.kind} without reaching it: a graze, which a change of the parameters "
                                       "that small turns into an event")

    def _guard_size(self, states, y: np.ndarray, e: int, guard) -> float:
        """What a guard's nearness to its level is judged against: the level and the quantity's size, or for a rate
        the run's speeds."""
        d, rate, tension, _ = self.scene.evaluate(states, y)
        if guard.quantity.startswith("internal:"):
            return abs(guard.level) + 1.0
        size = abs(guard.level) + abs(float({"d": d, "rate": rate, "tension": tension}[guard.quantity][e]))
        return max(size, self.v_scale) if guard.quantity == RATE else size

    def _set_numbers(self, e: int, state) -> dict[str, float]:
        """Element e's internal numbers that its events set (continuous's, less the ones integrated in y), by name in
        order."""
        integrated = set(self.scene.elements[e].law.ode_states)
        numbers = continuous(state.internal)
        return {name: numbers[name] for name in sorted(numbers) if name not in integrated}

    def _carry_internal(self, t: float, element: int, kind: str, before, after, y_before: np.ndarray,
                        moved: np.ndarray) -> None:
        """The sensitivities of the internal numbers an event sets (a plastic deformation where a spring unloads):
        the law's own event at the moved event point of the scene at each stencil point (event_sensitivity's)."""
        for e, (old, new) in enumerate(zip(before, after)):
            integrated = set(self.scene.elements[e].law.ode_states)
            if {k: v for k, v in old.internal.items() if k not in integrated} == \
                    {k: v for k, v in new.internal.items() if k not in integrated}:
                continue  # a change of mode alone (a contact that slips as the spring yields): nothing set
            numbers = self._set_numbers(e, new)
            path = self.scene.elements[e].path
            if e != element:
                self.no_derivative(t, f"{path} changes its internal variables at another element's event")
                return

            def event(scene, c, i):
                moved_states = shifted_states(before, self.dq, i, c)
                y = y_before + c * moved[:, i]
                scene.now = t
                d, rate, tension, _ = scene.evaluate(moved_states, y)
                return scene.elements[e].law.event(scene.live(moved_states, y)[e], kind, float(d[e]), float(rate[e]),
                                                   float(tension[e]))
            if not carry_numbers(self, e, list(numbers), new, event):
                self.no_derivative(t, f"{path}'s {kind} leads to another branch within the parameter's step: its "
                                   "derivatives on either side differ")
                return

    def _across_jump(self, t: float, before, y_before: np.ndarray, after, S: np.ndarray) -> np.ndarray:
        """S (m, P) across the ground's jump at t: x's and v's by event_edges.across_ground_jump (the jump's
        derivative, the modes it decides, a held constraint's projection), the numbers the jump sets carried; where it
        gives none, no derivative from t."""
        self._on_cut(t)  # every scene's forces just after t, as the modes are decided there
        rows = across_ground_jump(self, t, before, after, y_before, lambda i: S[:, i])
        if isinstance(rows, str):
            self.no_derivative(t, rows)
            return S
        S = S.copy()
        S[:2 * self.n] = rows.T
        return S

    def grid_tensions(self) -> tuple[np.ndarray, np.ndarray]:
        """Every nonsmooth element's whole tension on the grid (N, E) (the law's, a held contact's constraint force,
        the stiffness kept in K) and its scaled derivatives (N, P, E): the tension in each row's piece, differenced
        along each parameter at the stencil's points with the state moved by its sensitivity and the internal
        numbers by theirs; right limits at a restart, as the outputs; nan where the response has no derivative."""
        y, S = self.grid_states
        N, E = len(self.grid), len(self.scene.elements)
        tension, derived = np.full((N, E), np.nan), np.full((N, self.P, E), np.nan)
        cut = None
        for k, t in enumerate(self.grid.tolist()):
            if cut != (now := int(np.searchsorted(self.cuts, t, side="right"))):
                self._on_cut(t)  # every scene's forces on t's segment (a held contact's force reads them)
                cut = now
            states, dq = self.pieces[self.row_piece[k]][2], self.piece_dq[self.row_piece[k]]

            def whole(scene, c, i=None):
                moved = states if i is None else shifted_states(states, dq, i, c)
                scene.now = t
                d, _, law, _ = scene.evaluate(moved, y[k] if i is None else y[k] + c * S[k, :, i])
                return whole_tension(scene.elements, law, d)
            tension[k] = whole(self.scene, 0.0)
            for i in range(self.P):
                if np.isfinite(S[k, :, i]).all():
                    derived[k, i] = self.shifted_total(i, lambda scene, c, i=i: whole(scene, c, i))
        return tension, derived
