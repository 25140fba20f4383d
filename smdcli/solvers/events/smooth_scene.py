"""A nonsmooth scene whose modes may carry smooth nonlinear forces (Bouc-Wen, velocity-weakening and regularized friction,
cubic springs, quadratic dampers) and internal differential equations, evaluated at a state y = [x, v, q] for the
integrators (integrated.py): the same modes, guards and decisions as the exact solver's Scene (scene.py).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.elements import State
from smdcli.model import Model
from smdcli.solvers.events.scene import Scene


class SmoothScene(Scene):
    """A scene whose modes carry smooth nonlinear forces and internal differential equations: y = [x, v, q]."""

    forces_at_t = True

    def __init__(self, model: Model):
        super().__init__(model)
        self.q_slices = []
        start = 2 * self.n
        for element in self.elements:
            count = len(element.law.ode_states)
            self.q_slices.append(slice(start, start + count))
            start += count
        self.q_size = start - 2 * self.n
        self.now = 0.0  # the time evaluate() looks at (the driver sets it)
        self.force = None  # u(t) on the current segment

    def reseed(self, z: np.ndarray, t: float) -> None:
        """No generators here: forces are evaluated at t (y holds x, v and the laws' variables)."""

    def live(self, states: list[State], y: np.ndarray) -> list[State]:
        """The states with their internal ODE variables taken from y (a state, or rows of states: then each
        variable is the column of its values)."""
        out = []
        for element, state, part in zip(self.elements, states, self.q_slices):
            names = element.law.ode_states
            if names:
                values = np.moveaxis(y[..., part], -1, 0)
                state = State(state.mode, {**state.internal, **dict(zip(names, values))})
            out.append(state)
        return out

    def parts(self, states: list[State], t: float, y: np.ndarray):
        """(x'', T, q') at (t, y): the mode's linear part, its smooth forces, the held rows' constraint forces."""
        n = self.n
        x, v = y[:n], y[n:2 * n]
        mode = self.mode(states)
        model = self.model
        F = mode.g - mode.Kt @ x - mode.Ct @ v
        if model.signals:
            F = F + model.B @ self.force(t)
        if not model.is_linear and (model.cubic is not None or model.quadratic is not None):
            F = F - model.nonlinear_force(x, v)
        d = self.R @ x
        rate = self.R @ v + self.belts
        tension = np.zeros(self.E)
        qdot = np.zeros(self.q_size)
        live = self.live(states, y)
        for e, (element, state) in enumerate(zip(self.elements, live)):
            piece = element.law.piece(state)
            if piece.held:
                continue
            tension[e] = piece.stiffness * d[e] + piece.damping * rate[e] + piece.constant
            if piece.nonlinear is not None:
                extra = piece.nonlinear(d[e], rate[e], state.internal)
                tension[e] += extra
                F = F - extra * self.R[e]
            part = self.q_slices[e]
            if part.stop > part.start:
                qdot[part.start - 2 * n:part.stop - 2 * n] = element.law.ode(state, d[e], rate[e])
        accel = self.Minv @ F
        if mode.hold is not None:
            MG, S_pinv, _ = mode.hold
            mu = -S_pinv @ (mode.hold[2] @ accel)
            accel = accel + MG @ mu
            tension[list(mode.held)] = -mu
        return accel, tension, qdot

    def trend(self, states, y):
        """(the masses' jerk, the tensions' rates) at y: forward differences along the motion over a millionth of
        the fastest period (the modes' linear algebra is not at hand with smooth forces)."""
        n = self.n
        accel, tension, qdot = self.parts(states, self.now, y)
        rate = np.zeros_like(y)
        rate[:n], rate[n:2 * n], rate[2 * n:2 * n + self.q_size] = y[n:2 * n], accel, qdot
        mode = self.mode(states)
        omega = float(np.sqrt(np.max(np.abs(np.diag(self.Minv @ mode.Kt)), initial=0.0)))
        dt = 1e-6 / max(omega, 1.0)
        accel_next, tension_next, _ = self.parts(states, self.now + dt, y + dt * rate)
        return (accel_next - accel) / dt, (tension_next - tension) / dt

    def acceleration_size(self, states, y):
        """The size of the terms each mass's acceleration sums."""
        n = self.n
        mode = self.mode(states)
        size = np.abs(mode.Kt) @ np.abs(y[:n]) + np.abs(mode.Ct) @ np.abs(y[n:2 * n]) + np.abs(mode.g)
        if self.model.signals:
            size = size + np.abs(self.model.B) @ np.abs(self.force(self.now))
        return np.abs(self.Minv) @ size

    def evaluate(self, states, y):
        """(d, d', T, x'') at y, at the time the driver set."""
        n = self.n
        accel, tension, _ = self.parts(states, self.now, y)
        return self.R @ y[:n], self.R @ y[n:2 * n] + self.belts, tension, accel
