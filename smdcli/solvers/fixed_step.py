"""Fixed-step methods: the structural family (Newmark, HHT-alpha, generalized-alpha, central
difference) on M a + C v + K x + f_nl(x, v) = F(t), and classic Euler and RK4 on the state
equation, for stability studies.

The step is tol.dt (the scenario's solver.dt), or the output step when none is given. Each
stretch between force discontinuities is cut into equal steps no longer than dt, so a step
never straddles a jump; the method restarts there from equilibrium. Results on the output
grid come from cubic Hermite interpolation of (x, v) with their derivatives (v, a) at the
steps, which is as accurate as any of these methods.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
import time
from typing import ClassVar

import numpy as np

from smdcli.model import Model
from smdcli.result import Result, SolverStats
from smdcli.solvers.catalog import NEWMARK_SCHEMES
from smdcli.solvers.base import (MAX_STEPS, Solver, Tolerances, divergence_bound, diverged, force_function,
                                 make_result, segments)

NEWTON_MAXITER = 25
NEWTON_TOL = 1e-10


class StepFailed(Exception):
    """A fixed-step method could not take a step (Newton did not converge)."""


def step_count(span: float, dt: float) -> int:
    """Equal steps no longer than dt that cover span (a hair of rounding does not add a step)."""
    return max(1, math.ceil(span / dt * (1 - 1e-12)))


class FixedStep(Solver):
    """Shared driver: steps, divergence watch, Hermite output, statistics."""

    family = "fixed step"
    adaptive = False

    params: dict = {}

    def omega_limit(self) -> float:
        """Largest stable h * omega on an undamped linear scene (inf: unconditionally stable; 0: never)."""
        return math.inf

    def step_size(self, grid: np.ndarray, tol: Tolerances) -> float:
        """The requested dt, or the output spacing."""
        if tol.dt:
            return float(tol.dt)
        return float((grid[-1] - grid[0]) / max(len(grid) - 1, 1))

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        start = time.perf_counter()
        self.params = dict(tol.options)
        dt = self.step_size(grid, tol)
        max_steps = tol.max_steps or MAX_STEPS
        bound = divergence_bound(model, grid)
        n = model.n
        self.counts = {"nfev": 0, "njev": 0, "nlu": 0}
        # Nodes for the output interpolant; a restart at a force jump repeats the node with the new slope.
        times: list[float] = []
        states: list[np.ndarray] = []
        slopes: list[np.ndarray] = []
        y = np.concatenate([model.x0, model.v0])
        failure, t_reached, total, h_max = None, float(grid[0]), 0, 0.0
        for ta, tb in segments(model, grid):
            steps = step_count(tb - ta, dt)
            h = (tb - ta) / steps
            h_max = max(h_max, h)
            force = force_function(model, ta, tb)
            state = self.start(model, ta, y[:n], y[n:], force)
            times.append(ta)
            states.append(y)
            slopes.append(self.slope(state))
            budget = max_steps - total
            march = self._march_linear if model.is_linear else self._march
            new_states, new_slopes, failure = march(model, state, ta, h, min(steps, budget), force, bound)
            done = len(new_states)
            if failure is None and done < steps:
                failure = f"more than {max_steps} steps"
            total += done
            t_new = ta + h * np.arange(1, done + 1)
            if done == steps:
                t_new[-1] = tb
            times.extend(t_new)
            states.extend(new_states)
            slopes.extend(new_slopes)
            if done:
                t_reached = float(t_new[-1])
                y = new_states[-1]
            if failure:
                break
        out = _hermite(np.array(times), np.array(states), np.array(slopes), grid, t_reached)
        stats = SolverStats(
            method=self.name, requested_method=self.name, reason="", rtol=tol.rtol, atol=tol.atol, dt=h_max,
            wall_time_s=time.perf_counter() - start, success=failure is None,
            message="ok" if failure is None else f"failed at t = {t_reached:.6g} s: {failure}",
            steps_accepted=total, steps_rejected=0, **self.counts,
        )
        notes = () if tol.dt else (f"no solver.dt given: {self.name} stepped at the output spacing {dt:.6g} s",)
        return make_result(model, grid, out[:, :n], out[:, n:], stats,
                           t_failed=None if failure is None else t_reached, notes=notes)

    def _march(self, model, state, ta, h, steps, force, bound):
        """Up to `steps` steps from ta: ([x; v] after each, [v; a] after each, failure or None)."""
        states, slopes = [], []
        for i in range(steps):
            try:
                state = self.step(model, state, ta + i * h, h, force)
            except StepFailed as exc:
                return states, slopes, str(exc)
            y = self.state_vector(state)
            failure = diverged(y, bound)
            if failure:
                return states, slopes, failure
            states.append(y)
            slopes.append(self.slope(state))
        return states, slopes, None

    def _march_linear(self, model, state, ta, h, steps, force, bound):
        """_march for a linear model: one step is an affine map z' = A z + sum_j L_j u(t + c_j h), found by
        probing self.step once per state component and force sample; then a loop of matrix products."""
        A, loads, offsets, per_step = self._affine_step(model, state, h)
        u = _sampled_forces(model, force, ta + h * (np.arange(steps)[:, None] + np.array(offsets)[None, :]))
        drive = np.einsum("jkm,sjm->sk", loads, u) if len(offsets) and model.is_forced else np.zeros((steps, len(A)))
        z = np.concatenate(state)
        zs = np.empty((steps, len(z)))
        with np.errstate(all="ignore"):
            for i in range(steps):
                z = A @ z + drive[i]
                zs[i] = z
                if i % 256 == 255 and diverged(z, bound):
                    zs = zs[:i + 1]
                    break
            n2 = 2 * model.n
            states = zs[:, :n2]
            bad = ~np.isfinite(states).all(axis=1) | (np.abs(states).max(axis=1, initial=0.0) > bound)
        done = int(np.argmax(bad)) if bad.any() else len(states)
        failure = diverged(states[done], bound) if done < len(states) else None
        for key, value in per_step.items():
            self.counts[key] += value * done
        first = self.slope_offset * model.n
        return list(states[:done]), list(zs[:done, first:first + n2]), failure

    def _affine_step(self, model, state, h):
        """(A, L, offsets, counts per step) of one step of size h on a linear model, cached by h."""
        cache = getattr(self, "_affine_cache", None)
        if cache is not None and cache[0] == h:
            return cache[1]
        sizes = np.cumsum([len(part) for part in state])[:-1]
        size = sum(len(part) for part in state)
        requested: list[float] = []

        def recording(t):
            requested.append(t)
            return np.zeros(len(model.signals))

        before = dict(self.counts)
        self.step(model, np.split(np.zeros(size), sizes), 0.0, h, recording)  # factors what the step needs
        factorizations = self.counts["nlu"] - before["nlu"]
        self.counts.update(before)
        requested.clear()
        self.step(model, np.split(np.zeros(size), sizes), 0.0, h, recording)  # what each further step costs
        per_step = {key: self.counts[key] - before[key] for key in before}
        offsets = sorted({round(t / h, 12) for t in requested})
        A = np.column_stack([np.concatenate(self.step(model, np.split(e, sizes), 0.0, h, recording))
                             for e in np.eye(size)])
        loads = np.zeros((len(offsets), size, len(model.signals)))
        for j, c in enumerate(offsets):
            for m in range(len(model.signals)):
                def unit(t, c=c, m=m):
                    return np.eye(len(model.signals))[m] * (abs(t - c * h) <= 1e-9 * h)
                loads[j, :, m] = np.concatenate(self.step(model, np.split(np.zeros(size), sizes), 0.0, h, unit))
        self.counts.update(before)
        self.counts["nlu"] += factorizations
        self._affine_cache = (h, (A, loads, offsets, per_step))
        return self._affine_cache[1]

    # Hooks for each method: a state object, one step, and the state's [x, v] and [v, a].
    def start(self, model: Model, t: float, x: np.ndarray, v: np.ndarray, force):
        """The method's state at a (re)start."""
        raise NotImplementedError

    def step(self, model: Model, state, t: float, h: float, force):
        """The state one step of size h later."""
        raise NotImplementedError

    slope_offset = 1  # [v; a] starts this many DOF-blocks into the packed state [x, v, a]

    def state_vector(self, state) -> np.ndarray:
        """[x; v] of a state."""
        return np.concatenate([state[0], state[1]])

    def slope(self, state) -> np.ndarray:
        """[v; a] of a state."""
        return np.concatenate([state[1], state[2]])

    # Shared mechanics
    def equilibrium_acceleration(self, model: Model, t: float, x, v, force) -> np.ndarray:
        """a = M^-1 (F(t) - C v - K x - f_nl(x, v))."""
        self.counts["nfev"] += 1
        return model.Minv @ (self.applied(model, t, force) - self.internal(model, x, v))

    @staticmethod
    def applied(model: Model, t: float, force) -> np.ndarray:
        """External force per DOF at t."""
        return model.B @ force(t) if model.is_forced else np.zeros(model.n)

    @staticmethod
    def internal(model: Model, x, v) -> np.ndarray:
        """C v + K x + f_nl(x, v)."""
        f = model.C @ v + model.K @ x
        if not model.is_linear:
            f = f + model.nonlinear_force(x, v)
        return f


def _sampled_forces(model: Model, force, times: np.ndarray) -> np.ndarray:
    """force(t) at an array of times: (*times.shape, n_signals)."""
    flat = times.ravel()
    values = np.array([force(t) for t in flat]) if model.is_forced else np.zeros((len(flat), 0))
    return values.reshape(times.shape + (values.shape[-1],))


def _hermite(times, states, slopes, grid, t_reached) -> np.ndarray:
    """States on the grid by cubic Hermite interpolation between steps; NaN past t_reached."""
    out = np.full((len(grid), states.shape[1]), np.nan)
    reach = grid <= t_reached + 1e-12 * max(1.0, abs(t_reached))
    g = grid[reach]
    if len(times) == 1:
        out[reach] = states[0]
        return out
    j = np.clip(np.searchsorted(times, g, side="right") - 1, 0, len(times) - 2)
    h = times[j + 1] - times[j]
    s = ((g - times[j]) / h)[:, None]
    h = h[:, None]
    out[reach] = ((1 + 2 * s) * (1 - s) ** 2 * states[j] + s * (1 - s) ** 2 * h * slopes[j]
                  + s * s * (3 - 2 * s) * states[j + 1] + s * s * (s - 1) * h * slopes[j + 1])
    return out


class GeneralizedAlpha(FixedStep):
    """Chung-Hulbert generalized-alpha: M a(n+1-am) + f_int(n+1-af) = F(t(n+1-af)); Newmark and HHT are cases of it."""

    name = "generalized_alpha"
    description = "Chung-Hulbert generalized-alpha, implicit, second order"
    implicit = True
    order = 2
    DEFAULT_RHO_INF = 0.8

    def coefficients(self) -> tuple[float, float, float, float]:
        """(alpha_m, alpha_f, beta, gamma)."""
        rho = float(self.params.get("rho_inf", self.DEFAULT_RHO_INF))
        am, af = (2 * rho - 1) / (rho + 1), rho / (rho + 1)
        return am, af, 0.25 * (1 - am + af) ** 2, 0.5 - am + af

    def start(self, model, t, x, v, force):
        self.am, self.af, self.beta, self.gamma = self.coefficients()
        self._factor = None
        return (x, v, self.equilibrium_acceleration(model, t, x, v, force))

    def _effective(self, model, h, Kt, Ct):
        """dR/da and its factorization (counted as one LU)."""
        self.counts["nlu"] += 1
        S = (1 - self.am) * model.M + (1 - self.af) * (self.gamma * h * Ct + self.beta * h * h * Kt)
        return np.linalg.inv(S)

    def step(self, model, state, t, h, force):
        x_n, v_n, a_n = state
        am, af, beta, gamma = self.am, self.af, self.beta, self.gamma
        x_pred = x_n + h * v_n + h * h * (0.5 - beta) * a_n
        v_pred = v_n + h * (1 - gamma) * a_n
        F = self.applied(model, t + (1 - af) * h, force)
        f_n = self.internal(model, x_n, v_n) if af else 0.0
        rest = am * (model.M @ a_n) + af * f_n - F

        def residual(a):
            x, v = x_pred + beta * h * h * a, v_pred + gamma * h * a
            self.counts["nfev"] += 1
            return (1 - am) * (model.M @ a) + (1 - af) * self.internal(model, x, v) + rest, x, v

        a = a_n
        if model.is_linear:
            if self._factor is None or self._factor[0] != h:
                self._factor = (h, self._effective(model, h, model.K, model.C))
            r, _, _ = residual(a)
            a = a - self._factor[1] @ r
            return (x_pred + beta * h * h * a, v_pred + gamma * h * a, a)
        scale = np.abs(a_n).max() + np.abs(model.Minv @ F).max() + 1e-300
        for _ in range(NEWTON_MAXITER):
            r, x, v = residual(a)
            self.counts["njev"] += 1
            Kt, Ct = model.tangent(x, v)
            da = -self._effective(model, h, Kt, Ct) @ r
            a = a + da
            if not np.all(np.isfinite(a)):
                raise StepFailed("Newton iteration diverged")
            if np.abs(da).max() <= NEWTON_TOL * max(scale, np.abs(a).max()):
                return (x_pred + beta * h * h * a, v_pred + gamma * h * a, a)
        raise StepFailed(f"Newton did not converge in {NEWTON_MAXITER} iterations")


class Newmark(GeneralizedAlpha):
    """Newmark-beta: average acceleration (beta 1/4, gamma 1/2) by default, or linear acceleration (1/6, 1/2)."""

    name = "newmark"
    description = "Newmark-beta, average acceleration unless beta/gamma or scheme say otherwise"
    SCHEMES: ClassVar[dict[str, tuple[float, float]]] = NEWMARK_SCHEMES

    def coefficients(self):
        beta, gamma = self.SCHEMES[self.params.get("scheme", "average_acceleration")]
        return 0.0, 0.0, float(self.params.get("beta", beta)), float(self.params.get("gamma", gamma))

    def omega_limit(self):
        _, _, beta, gamma = self.coefficients()
        if 2 * beta >= gamma >= 0.5:
            return math.inf
        return 1 / math.sqrt(gamma / 2 - beta) if gamma / 2 > beta else 0.0


class HHT(GeneralizedAlpha):
    """Hilber-Hughes-Taylor alpha in Hilber's convention, alpha in [-1/3, 0]; alpha = 0 is average acceleration."""

    name = "hht"
    description = "HHT-alpha (Hilber, Hughes, Taylor 1977), implicit, second order, damps high modes"
    DEFAULT_ALPHA = -0.1

    def coefficients(self):
        af = -float(self.params.get("alpha", self.DEFAULT_ALPHA))
        return 0.0, af, 0.25 * (1 + af) ** 2, 0.5 + af


class CentralDifference(GeneralizedAlpha):
    """Central difference as Newmark beta = 0, gamma = 1/2: stiffness never enters the step's matrix, only
    M + h/2 C (diagonal, hence explicit, for lumped masses and dampers to ground)."""

    name = "central_difference"
    description = "explicit central difference (Newmark beta 0, gamma 1/2), second order, stable for h * omega_max <= 2"
    implicit = False

    def coefficients(self):
        return 0.0, 0.0, 0.0, 0.5

    def omega_limit(self):
        return 2.0


class _StateStepper(FixedStep):
    """Explicit one-step methods on the first-order state equation y' = f(t, y)."""

    def start(self, model, t, x, v, force):
        y = np.concatenate([x, v])
        return (y, self._f(model, t, y, force))

    def _f(self, model, t, y, force):
        self.counts["nfev"] += 1
        u = force(t) if model.is_forced else np.empty(0)
        return model.rhs(t, y, u)

    slope_offset = 2  # packed state [y, f] = [x, v, v, a]

    def state_vector(self, state):
        return state[0]

    def slope(self, state):
        return state[1]


class Euler(_StateStepper):
    """Explicit (forward) Euler: first order; on an undamped scene its energy grows at every step size."""

    name = "euler"
    description = "explicit Euler, first order, for stability studies"
    order = 1

    def omega_limit(self):
        return 0.0

    def step(self, model, state, t, h, force):
        y, f = state
        y_new = y + h * f
        return (y_new, self._f(model, t + h, y_new, force))


class RK4(_StateStepper):
    """The classic fourth-order Runge-Kutta method; stable on the imaginary axis for h * omega <= 2 sqrt(2)."""

    name = "rk4"
    description = "classic Runge-Kutta, fourth order, fixed step, for stability studies"
    order = 4

    def omega_limit(self):
        return 2 * math.sqrt(2)

    def step(self, model, state, t, h, force):
        y, k1 = state
        k2 = self._f(model, t + 0.5 * h, y + 0.5 * h * k1, force)
        k3 = self._f(model, t + 0.5 * h, y + 0.5 * h * k2, force)
        k4 = self._f(model, t + h, y + h * k3, force)
        y_new = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return (y_new, self._f(model, t + h, y_new, force))
