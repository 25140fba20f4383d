"""Fixed-step methods: the structural family (Newmark, Hilber's alpha, generalized-alpha,
central difference) on M a + C v + K x + f_nl(x, v) = F(t), and classic Euler and RK4 on the state
equation, for stability studies; all stepped by the compiled kernel smdcli.kernels.fixed.

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
from smdcli.solvers.base import MAX_STEPS, Solver, Tolerances, cuts, divergence_bound, make_result
from smdcli.solvers.registry import NEWMARK_SCHEMES
from smdcli.solvers.integrators.compiled import failure_text, warm


class FixedStep(Solver):
    """Shared driver: the compiled march, its statistics and failure messages."""

    compiled = True
    adaptive = False
    kernel_method: ClassVar[str] = "GENERALIZED_ALPHA"  # the name of a method id in smdcli.kernels.fixed

    params: dict = {}

    def omega_limit(self) -> float:
        """Largest stable h * omega on an undamped linear scene (inf: unconditionally stable; 0: never)."""
        return math.inf

    def coefficients(self) -> tuple[float, float, float, float]:
        """(alpha_m, alpha_f, beta, gamma) of the generalized-alpha family; unused by Euler and RK4."""
        return 0.0, 0.0, 0.0, 0.0

    def step_size(self, grid: np.ndarray, tol: Tolerances) -> float:
        """The requested dt, or the output spacing."""
        if tol.dt:
            return float(tol.dt)
        return float((grid[-1] - grid[0]) / max(len(grid) - 1, 1))

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        from smdcli.kernels import fixed
        from smdcli.kernels.arrays import model_arrays
        from smdcli.kernels.rhs import work_size

        warm("fixed")
        start = time.perf_counter()
        self.params = dict(tol.options)
        dt = self.step_size(grid, tol)
        max_steps = tol.max_steps or MAX_STEPS
        bound = divergence_bound(model, grid)
        arrays = model_arrays(model)
        y0 = np.concatenate([model.x0, model.v0]).astype(float)
        out = np.full((len(grid), len(y0)), np.nan)
        out[0] = y0
        counts, floats = np.zeros(4, dtype=np.int64), np.zeros(2)
        status = fixed.march(arrays, getattr(fixed, self.kernel_method), np.array(self.coefficients(), dtype=float), y0,
                             np.asarray(grid, dtype=float), cuts(model, grid, tol.breakpoints), dt, int(max_steps),
                             float(bound), out, counts, floats, np.zeros(work_size(arrays)))
        t_reached = float(floats[fixed.T_REACHED])
        if status == fixed.OK:
            failure = None
        elif status == fixed.NEWTON_FAILED:
            failure = f"Newton did not converge in {fixed.NEWTON_MAXITER} iterations"
        else:
            failure = failure_text(status, max_steps, bound)
        stats = SolverStats(
            method=self.name, requested_method=self.name, reason="", rtol=tol.rtol, atol=tol.atol,
            dt=float(floats[fixed.H_MAX]), wall_time_s=time.perf_counter() - start, success=failure is None,
            message="ok" if failure is None else f"failed at t = {t_reached:.6g} s: {failure}",
            steps_accepted=int(counts[fixed.STEPS]), steps_rejected=0, nfev=int(counts[fixed.NFEV]),
            njev=int(counts[fixed.NJEV]), nlu=int(counts[fixed.NLU]),
        )
        notes = () if tol.dt else (f"no solver.dt given: {self.name} stepped at the output spacing {dt:.6g} s",)
        n = model.n
        return make_result(model, grid, out[:, :n], out[:, n:], stats,
                           t_failed=None if failure is None else t_reached, notes=notes)


class GeneralizedAlpha(FixedStep):
    """Chung-Hulbert generalized-alpha: M a(n+1-am) + f_int(n+1-af) = F(t(n+1-af)); Newmark and Hilber's alpha are
    cases of it."""

    implicit = True
    order = 2
    DEFAULT_RHO_INF = 0.8

    def coefficients(self) -> tuple[float, float, float, float]:
        """(alpha_m, alpha_f, beta, gamma)."""
        rho = float(self.params.get("rho_inf", self.DEFAULT_RHO_INF))
        am, af = (2 * rho - 1) / (rho + 1), rho / (rho + 1)
        return am, af, 0.25 * (1 - am + af) ** 2, 0.5 - am + af


class Newmark(GeneralizedAlpha):
    """Newmark-beta: average acceleration (beta 1/4, gamma 1/2) by default, or linear acceleration (1/6, 1/2)."""

    SCHEMES: ClassVar[dict[str, tuple[float, float]]] = NEWMARK_SCHEMES

    def coefficients(self):
        beta, gamma = self.SCHEMES[self.params.get("scheme", "average_acceleration")]
        return 0.0, 0.0, float(self.params.get("beta", beta)), float(self.params.get("gamma", gamma))

    def omega_limit(self):
        _, _, beta, gamma = self.coefficients()
        if 2 * beta >= gamma >= 0.5:
            return math.inf
        return 1 / math.sqrt(gamma / 2 - beta) if gamma / 2 > beta else 0.0


class HilberAlpha(GeneralizedAlpha):
    """Hilber, Hughes and Taylor's alpha in Hilber's convention, alpha in [-1/3, 0]; alpha = 0 is average
    acceleration."""

    DEFAULT_ALPHA = -0.1

    def coefficients(self):
        af = -float(self.params.get("alpha", self.DEFAULT_ALPHA))
        return 0.0, af, 0.25 * (1 + af) ** 2, 0.5 + af


class CentralDifference(GeneralizedAlpha):
    """Central difference as Newmark beta = 0, gamma = 1/2: stiffness never enters the step's matrix, only
    M + h/2 C (diagonal, hence explicit, for lumped masses and dampers to ground)."""

    implicit = False

    def coefficients(self):
        return 0.0, 0.0, 0.0, 0.5

    def omega_limit(self):
        return 2.0


class Euler(FixedStep):
    """Explicit (forward) Euler: first order; on an undamped scene its energy grows at every step size."""

    order = 1
    kernel_method = "EULER"

    def omega_limit(self):
        return 0.0


class RK4(FixedStep):
    """The classic fourth-order Runge-Kutta method; stable on the imaginary axis for h * omega <= 2 sqrt(2)."""

    order = 4
    kernel_method = "RK4"

    def omega_limit(self):
        return 2 * math.sqrt(2)
