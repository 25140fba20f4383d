"""MATLAB's low-order stiff solvers, written as scipy OdeSolver subclasses.

- ode23s: the Rosenbrock 2(3) pair of Shampine and Reichelt, "The MATLAB ODE
  Suite" (SIAM J. Sci. Comput. 18, 1997), with its free second-order
  interpolant.
- ode23t: the trapezoidal rule. Its local error -h^3/12 y''' is estimated
  from y'' = J f + f_t at both ends of the step.
- ode23tb: TR-BDF2 of Bank et al. and Hosea and Shampine ("Analysis and
  implementation of TR-BDF2", Appl. Numer. Math. 20, 1996): a trapezoidal
  stage to t + gamma h, gamma = 2 - sqrt(2), then BDF2; both stages share one
  iteration matrix.

All three take the model's analytic Jacobian. Error estimates of the implicit
ones are filtered through the iteration matrix, as in Shampine's codes, so
that stiff components that have decayed do not hold the step down. Error
norms are scipy's: RMS of err / (atol + rtol * max(|y|, |y_new|)).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import DenseOutput, OdeSolver
from scipy.linalg import lu_factor, lu_solve

EPS = np.finfo(float).eps
SAFETY = 0.8
MIN_FACTOR = 0.2
MAX_FACTOR = 5.0
NEWTON_MAXITER = 5


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x))) if x.size else 0.0


class IterationMatrix:
    """A factored matrix W; solve(b) = W^-1 b. Small systems keep the inverse: scipy's LU calls cost
    more in overhead than the arithmetic for a few DOFs."""

    SMALL = 32

    def __init__(self, W: np.ndarray):
        if len(W) <= self.SMALL:
            self.inverse, self.lu = np.linalg.inv(W), None
        else:
            self.inverse, self.lu = None, lu_factor(W, overwrite_a=True, check_finite=False)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """W^-1 b."""
        if self.lu is None:
            return self.inverse @ b
        return lu_solve(self.lu, b, check_finite=False)


class HermiteDense(DenseOutput):
    """Cubic Hermite interpolant through (y0, f0) and (y1, f1): third order, continuous with its neighbours."""

    def __init__(self, t0, t1, y0, f0, y1, f1):
        super().__init__(t0, t1)
        self.h = t1 - t0
        self.y0, self.f0, self.y1, self.f1 = y0, f0, y1, f1

    def _call_impl(self, t):
        s = (np.asarray(t) - self.t_old) / self.h
        h00 = (1 + 2 * s) * (1 - s) ** 2
        h10 = s * (1 - s) ** 2
        h01 = s * s * (3 - 2 * s)
        h11 = s * s * (s - 1)
        y = (np.multiply.outer(self.y0, h00) + np.multiply.outer(self.h * self.f0, h10)
             + np.multiply.outer(self.y1, h01) + np.multiply.outer(self.h * self.f1, h11))
        return y


class _OneStep(OdeSolver):
    """Shared machinery: tolerances, first step, Jacobian and its reuse, step-size control."""

    error_order = 3  # the estimate is O(h^3)

    def __init__(self, fun, t0, y0, t_bound, jac, rtol=1e-3, atol=1e-6, first_step=None, max_step=np.inf,
                 time_dependent=True, constant_jacobian=False, vectorized=False):
        super().__init__(fun, t0, y0, t_bound, vectorized)
        self.rtol = max(float(rtol), 100 * EPS)
        self.atol = np.asarray(atol, dtype=float)
        self.max_step = float(max_step)
        self.jac_function = jac
        self.time_dependent = time_dependent
        self.constant_jacobian = constant_jacobian
        self.njev = 0
        self.nlu = 0
        self.n_rejected = 0
        self.f = self.fun(self.t, self.y)
        self.J = self._jacobian(self.t, self.y)
        self.h = first_step if first_step is not None else self._first_step()
        self.interpolant = None
        self.newton_tol = max(10 * EPS / self.rtol, min(0.03, self.rtol ** 0.5))

    # ------------------------------------------------------------ helpers
    def _jacobian(self, t, y):
        """J at (t, y); evaluated once per point (the end of one step is the start of the next)."""
        if self.constant_jacobian and getattr(self, "J", None) is not None:
            return self.J
        cached = getattr(self, "_last_jacobian", None)
        if cached is not None and cached[0] == t and np.array_equal(cached[1], y):
            return cached[2]
        self.njev += 1
        J = np.asarray(self.jac_function(t, y), dtype=float)
        self._last_jacobian = (t, y, J)
        return J

    def _scale(self, y, y_new=None):
        size = np.abs(y) if y_new is None else np.maximum(np.abs(y), np.abs(y_new))
        return self.atol + self.rtol * size

    def _first_step(self) -> float:
        """Hairer, Norsett and Wanner's starting step (Solving ODEs I, II.4)."""
        span = abs(self.t_bound - self.t)
        if span == 0:
            return 0.0
        scale = self._scale(self.y)
        d0, d1 = _rms(self.y / scale), _rms(self.f / scale)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, span)
        f1 = self.fun(self.t + self.direction * h0, self.y + self.direction * h0 * self.f)
        d2 = _rms((f1 - self.f) / scale) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1 / self.error_order)
        return min(100 * h0, h1, span, self.max_step)

    def _time_derivative(self, t, y, f):
        """df/dt at fixed y by a forward difference; zero for an autonomous system."""
        if not self.time_dependent:
            return np.zeros_like(y)
        delta = math.sqrt(EPS) * max(abs(t), 1.0)
        return (self.fun(t + delta, y) - f) / delta

    def _factor(self, coefficient):
        """The iteration matrix I - coefficient * J, factored (counted as one LU)."""
        self.nlu += 1
        return IterationMatrix(np.eye(self.n) - coefficient * self.J)

    def _factor_after(self, error_norm: float, rejected: bool) -> float:
        if error_norm == 0:
            return MAX_FACTOR if not rejected else 1.0
        factor = SAFETY * error_norm ** (-1 / self.error_order)
        return min(1.0 if rejected else MAX_FACTOR, max(MIN_FACTOR, factor))

    def _newton(self, lu, residual, z, scale):
        """Simplified Newton on residual(z) = 0 with iteration matrix lu; (z, converged)."""
        rate = None
        dz_norm_old = None
        for _ in range(NEWTON_MAXITER):
            dz = -lu.solve(residual(z))
            z = z + dz
            if self.constant_jacobian:  # linear: exact Jacobian, so one iteration solves the system
                return z, True
            dz_norm = _rms(dz / scale)
            if dz_norm_old is not None:
                rate = dz_norm / dz_norm_old
                if rate >= 1:
                    return z, False
            if dz_norm == 0 or (rate is not None and rate / (1 - rate) * dz_norm < self.newton_tol) \
                    or dz_norm < 1e-3 * self.newton_tol:
                return z, True
            dz_norm_old = dz_norm
        return z, False

    # ------------------------------------------------------------- driving
    def _step_impl(self):
        t, y = self.t, self.y
        span = abs(self.t_bound - t)
        min_step = 10 * abs(np.nextafter(t, self.direction * np.inf) - t)
        h = min(self.h, self.max_step, span)
        if span - h < min_step:  # do not leave a sliver before the bound
            h = span
        rejected = False
        self.J = self._jacobian(t, y)  # current at every step start, so a failed corrector means a smaller h
        while True:
            if h < min_step:
                return False, self.TOO_SMALL_STEP
            attempt = self._attempt(t, y, self.direction * h)
            if attempt is None:
                h *= 0.5
                rejected = True
                self.n_rejected += 1
                continue
            y_new, f_new, error_norm, interpolant = attempt
            if error_norm <= 1:
                break
            h *= self._factor_after(error_norm, True)
            rejected = True
            self.n_rejected += 1
        h_next = h * self._factor_after(error_norm, rejected)
        self.t = t + self.direction * h
        self.y, self.f = y_new, f_new
        self.h = h_next
        self.interpolant = interpolant
        return True, None

    def _attempt(self, t, y, h):
        """One try of size h: (y_new, f_new, error norm, interpolant) or None if the corrector failed."""
        raise NotImplementedError

    def _dense_output_impl(self):
        return self.interpolant


class Rosenbrock23(_OneStep):
    """ode23s: the linearly implicit Rosenbrock 2(3) pair of Shampine and Reichelt, L-stable, W^-1 each step."""

    d = 1 / (2 + math.sqrt(2))
    e32 = 6 + math.sqrt(2)

    def _attempt(self, t, y, h):
        d, e32, f0 = self.d, self.e32, self.f
        T = self._time_derivative(t, y, f0)
        lu = self._factor(h * d)
        k1 = lu.solve(f0 + h * d * T)
        f1 = self.fun(t + 0.5 * h, y + 0.5 * h * k1)
        k2 = lu.solve(f1 - k1) + k1
        y_new = y + h * k2
        f2 = self.fun(t + h, y_new)
        k3 = lu.solve(f2 - e32 * (k2 - f1) - 2 * (k1 - f0) + h * d * T)
        error = h / 6 * (k1 - 2 * k2 + k3)
        error_norm = _rms(error / self._scale(y, y_new))
        return y_new, f2, error_norm, RosenbrockDense(t, t + h, y, k1, k2, d)


class RosenbrockDense(DenseOutput):
    """ode23s's own interpolant: y + h (s(1-s) k1 + s(s-2d) k2) / (1-2d), second order."""

    def __init__(self, t0, t1, y0, k1, k2, d):
        super().__init__(t0, t1)
        self.h, self.y0, self.k1, self.k2, self.d = t1 - t0, y0, k1, k2, d

    def _call_impl(self, t):
        s = (np.asarray(t) - self.t_old) / self.h
        a = s * (1 - s) / (1 - 2 * self.d)
        b = s * (s - 2 * self.d) / (1 - 2 * self.d)
        return (self.y0[:, None] if np.ndim(s) else self.y0) + self.h * (
            np.multiply.outer(self.k1, a) + np.multiply.outer(self.k2, b))


class Trapezoid(_OneStep):
    """ode23t: the trapezoidal rule, A-stable and without numerical damping, solved by simplified Newton."""

    second: tuple[float, np.ndarray] | None = None  # (t, y'') at the current step's start

    def _second_derivative(self, t, y, f):
        return self._jacobian(t, y) @ f + self._time_derivative(t, y, f)

    def _attempt(self, t, y, h):
        f0 = self.f
        lu = self._factor(0.5 * h)
        scale = self._scale(y)

        def residual(z):
            return z - y - 0.5 * h * (f0 + self.fun(t + h, z))

        z, converged = self._newton(lu, residual, y + h * f0, scale)
        if not converged:
            return None
        f1 = self.fun(t + h, z)
        if self.second is None or self.second[0] != t:
            self.second = (t, self._second_derivative(t, y, f0))
        y2_new = self._second_derivative(t + h, z, f1)
        estimate = -(h * h / 12) * (y2_new - self.second[1])
        error = lu.solve(estimate)
        error_norm = _rms(error / self._scale(y, z))
        if error_norm <= 1:
            self.second = (t + h, y2_new)  # the next step starts here
        return z, f1, error_norm, HermiteDense(t, t + h, y, f0, z, f1)


class TRBDF2(_OneStep):
    """ode23tb: a trapezoidal stage to t + gamma h, then BDF2 to t + h; L-stable, one iteration matrix."""

    gamma = 2 - math.sqrt(2)
    d = gamma / 2  # = (1 - gamma) / (2 - gamma): both stages' implicit coefficient
    # Local error constant of TR-BDF2: LTE = C h^3 y''' (Hosea and Shampine 1996).
    C = (-3 * gamma**2 + 4 * gamma - 2) / (12 * (2 - gamma))

    def _attempt(self, t, y, h):
        g, d, f0 = self.gamma, self.d, self.f
        lu = self._factor(d * h)
        scale = self._scale(y)

        def tr_residual(z):
            return z - y - d * h * (f0 + self.fun(t + g * h, z))

        z1, converged = self._newton(lu, tr_residual, y + g * h * f0, scale)
        if not converged:
            return None
        f1 = self.fun(t + g * h, z1)
        a1 = 1 / (g * (2 - g))
        a0 = (1 - g) ** 2 / (g * (2 - g))

        def bdf_residual(z):
            return z - a1 * z1 + a0 * y - d * h * self.fun(t + h, z)

        z2, converged = self._newton(lu, bdf_residual, z1 + (1 - g) * h * f1, scale)
        if not converged:
            return None
        f2 = self.fun(t + h, z2)
        # h^3 y''' from the second divided difference of f over t, t + gamma h, t + h.
        h3y3 = 2 * h * (f0 / g - f1 / (g * (1 - g)) + f2 / (1 - g))
        error = lu.solve(self.C * h3y3)
        error_norm = _rms(error / self._scale(y, z2))
        return z2, f2, error_norm, HermiteDense(t, t + h, y, f0, z2, f2)
