"""Where a mode's guards reach their levels along the exact flow (piecewise.py's event location): a crossing
bracketed on a substep, a touch without a crossing caught where the guard's slope turns, a return to the level just
left, each root found by Brent's method to rounding on the guard's Taylor polynomial (flow.guard_polynomial) where it
is good to rounding, else on the exponential.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.elements.base import D, RATE
from smdcli.solvers.exact.flow import Flow
from smdcli.solvers.events.scene import TOUCH, Mode, at_level, event_root

RETURN_SAMPLES = 32  # samples of a substep in which a guard left at its level may have come back and gone again


class Crossings:
    """The event location of PiecewiseRun (which holds v_scale, the run's speeds so far)."""

    v_scale: float

    def first_crossing(self, flow: Flow, mode: Mode, z0: np.ndarray, z1: np.ndarray, h: float):
        """(tau, element, guard) of the earliest guard crossing in (0, h], or None."""
        best = None
        for e, guard, row, const in mode.guards:
            g0, g1 = float(row @ z0 + const), float(row @ z1 + const)
            s = guard.direction
            tau = None
            level = self._level(guard, row, const, z0)
            at = abs(g0) <= level  # at its level (on either side of it by rounding)
            if at and guard.quantity == D and s * float(row @ (mode.A @ z0 + mode.b)) > TOUCH * self.v_scale:
                tau = 0.0  # leaving its level past it now (a spring yielding onto a stop it is at), however soon back
            elif at and s * g1 >= 0:
                tau = self._return(flow, mode, z0, row, const, s, h)
            elif s * g0 < 0 <= s * g1:
                tau = self._root(flow, mode, z0, row, const, 0.0, h)
            elif s * g0 < -level and s * g1 < 0:  # a touch inside the substep, not at its start: where the slope turns
                slope0 = float(row @ (mode.A @ z0 + mode.b))
                slope1 = float(row @ (mode.A @ z1 + mode.b))
                if s * slope0 > 0 > s * slope1:
                    tau = self._touch(flow, mode, z0, row, const, s, h)
            if tau is not None and (best is None or tau < best[0]):
                best = (tau, e, guard)
        return best

    def _level(self, guard, row: np.ndarray, const: float, z0: np.ndarray) -> float:
        """How close to its level a guard's value at z0 is rounding of it: of the terms it sums, or for a rate of the
        speeds it was computed from."""
        size = float(np.abs(row) @ np.abs(z0))
        return at_level(max(size, self.v_scale) if guard.quantity == RATE else size, const)

    @staticmethod
    def _along(flow: Flow, mode: Mode, z0: np.ndarray, row: np.ndarray, const: float, h: float):
        """row z(tau) + const for tau in [0, h], as a function of tau: the guard's Taylor polynomial where it is good
        to rounding, else the exponential's step to each tau."""
        return flow.guard_polynomial(z0, mode.b, row, const, h) or \
            (lambda tau: float(row @ flow.at(z0, mode.b, tau) + const))

    def _turn_top(self, flow: Flow, mode: Mode, z0: np.ndarray, row: np.ndarray, const: float,
                  h: float) -> tuple[float, float]:
        """Where a guard's slope turns in (0, h] (rising at the start, falling at h), and the guard's value there."""
        turn = self._root(flow, mode, z0, row @ mode.A, float(row @ mode.b), 0.0, h)
        return turn, self._along(flow, mode, z0, row, const, h)(turn)

    def _touch(self, flow: Flow, mode: Mode, z0: np.ndarray, row: np.ndarray, const: float, s: float, h: float):
        """Where a guard below its level at both ends of a step, rising at its start and falling at its end, reaches
        its level before its turn, or None where its top stays below."""
        turn, top = self._turn_top(flow, mode, z0, row, const, h)
        if s * top >= 0:
            return self._root(flow, mode, z0, row, const, 0.0, turn)
        return None

    def turn_may_hold_event(self, flow: Flow, mode: Mode, guard, row: np.ndarray, const: float, z0: np.ndarray,
                            h: float) -> bool:
        """Whether first_crossing could find an event of this guard on a step from z0 that a batch flagged as a
        possible touch (below its level at both ends, its slope turning): a start at its level, or a top that
        comes within turn_margin of it. A top further below lets the batch go on where the single step would find
        nothing."""
        if guard.direction * float(row @ z0 + const) >= -self._level(guard, row, const, z0):
            return True
        return guard.direction * self._turn_top(flow, mode, z0, row, const, h)[1] >= \
            -self.turn_margin(guard, row, const, z0)

    def turn_margin(self, guard, row: np.ndarray, const: float, z0: np.ndarray) -> float:
        """How far below its level a guard's top may stay and still end a batch: none (only a top that reaches its
        level holds an event)."""
        return 0.0

    def _return(self, flow: Flow, mode: Mode, z0: np.ndarray, row: np.ndarray, const: float, s: float, h: float):
        """Where a guard the event just taken left at its level comes back to it in (0, h], from the bottom of its
        excursion below it (its slope's root; a dip right after the start found by halving towards it, the return
        then bracketed by doubling; or the lowest of RETURN_SAMPLES samples). If it never went below, it goes on
        past its level from here: an event now (a spring that yields where its stop is met, the two at one
        instant); None where it only stays at its level to rounding (a spring on its surface held by a contact)."""
        along = self._along(flow, mode, z0, row, const, h)
        value = lambda tau: s * along(tau)  # noqa: E731
        rate = lambda z: s * float(row @ (mode.A @ z + mode.b))  # noqa: E731
        level = at_level(float(np.abs(row) @ np.abs(z0)), const)  # below it by no more: at it (a mass at rest there)
        lo, hi = None, h
        leaving = rate(z0) < 0
        if leaving and rate(flow.at(z0, mode.b, h)) > 0:  # one turn: the bottom where the slope changes sign
            lo = self._root(flow, mode, z0, row @ mode.A, float(row @ mode.b), 0.0, h)
        if leaving and (lo is None or value(lo) >= -level):  # a rebound that lands again long before the samples
            lo = next((tau for tau in h * 0.5 ** np.arange(1, 60) if value(tau) < -level), None)
            if lo is not None:
                hi = next((tau for tau in lo * 2.0 ** np.arange(1, 60) if tau >= h or value(tau) >= 0), h)
                hi = min(hi, h)
        if lo is None or value(lo) >= -level:
            taus = h * np.arange(1, RETURN_SAMPLES) / RETURN_SAMPLES
            values = np.array([value(tau) for tau in taus])
            if values.min() >= -level:
                return 0.0 if value(h) > level else None
            lo = float(taus[int(np.argmin(values))])
        return self._root(flow, mode, z0, row, const, lo, hi)

    def _root(self, flow: Flow, mode: Mode, z0: np.ndarray, row: np.ndarray, const: float, lo: float,
              hi: float) -> float:
        """The root of row z(tau) + const in [lo, hi] (a sign change there), to rounding."""
        value = self._along(flow, mode, z0, row, const, hi)
        f_lo, f_hi = value(lo), value(hi)
        if f_lo == 0:
            return lo
        if f_hi == 0 or f_lo * f_hi > 0:
            return hi
        return event_root(value, lo, hi, hi - lo)
