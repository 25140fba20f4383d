"""scipy integrators, driven step by step between force discontinuities.

Driving scipy's OdeSolver classes directly (rather than through solve_ivp)
lets smd restart at every force breakpoint, count accepted and rejected
steps and stop at divergence with the time reached. The explicit pairs run
compiled (smdcli.solvers.integrators.compiled); scipy's stay here as `scipy:RK45`,
`scipy:RK23` and `scipy:DOP853`, an independent cross-check.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import contextlib
import time
from typing import Callable, ClassVar

import numpy as np

from smdcli.model import Model
from smdcli.result import Result, SolverStats
from smdcli.solvers.base import (MAX_STEPS, Solver, Tolerances, divergence_bound, diverged, force_function,
                                 make_result, segments)
from smdcli.solvers.integrators.compiled import warm
from smdcli.solvers.registry import OWN_SOLVERS


@contextlib.contextmanager
def _count_attempts(module, name: str, key: Callable):
    """Count the step attempts of an implicit scipy method by wrapping its per-attempt solve."""
    original = getattr(module, name)
    keys: list = []

    def wrapped(*args, **kwargs):
        k = key(*args)
        if not keys or keys[-1] != k:  # a Jacobian refresh retries the same attempt
            keys.append(k)
        return original(*args, **kwargs)

    setattr(module, name, wrapped)
    try:
        yield keys
    finally:
        setattr(module, name, original)


def _rhs(model: Model, ta: float, tb: float):
    """Model.rhs on the segment [ta, tb], with force values that never take the next segment's jump."""
    u = force_function(model, ta, tb) if model.is_forced else (lambda t: np.empty(0))

    def fun(t, y):
        return model.rhs(t, y, u(t))

    return fun


def _compiled_rhs(model: Model, ta: float, tb: float):
    """_rhs from the compiled kernel (about 3 us a call from Python instead of 7), for the Fortran integrators."""
    from smdcli.kernels.arrays import model_arrays
    from smdcli.kernels.rhs import state_rhs, work_size

    arrays = model_arrays(model)
    work, scratch, mid = np.zeros(work_size(arrays)), np.zeros((1, 1)), 0.5 * (ta + tb)

    def fun(t, y):
        dy = np.empty(len(y))
        state_rhs(arrays, float(t), np.ascontiguousarray(y, dtype=float), bool(t >= mid), dy, work, scratch)
        return dy

    return fun


def _initial(model: Model, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Output rows (NaN until reached) with the initial state in row 0, that state, and the divergence bound."""
    y = np.concatenate([model.x0, model.v0])
    out = np.full((len(grid), 2 * model.n), np.nan)
    out[0] = y
    return out, y, divergence_bound(model, grid)


def _finish(solver: Solver, model: Model, grid: np.ndarray, out: np.ndarray, tol: Tolerances, start: float,
            counts: dict, failure: str | None, t_reached: float) -> Result:
    """The Result of an integration that stopped at t_reached, failed if `failure` says why."""
    stats = SolverStats(
        method=solver.name, requested_method=solver.name, reason="", rtol=tol.rtol, atol=tol.atol,
        wall_time_s=time.perf_counter() - start, success=failure is None,
        message="ok" if failure is None else f"failed at t = {t_reached:.6g} s: {failure}", **counts,
    )
    n = model.n
    return make_result(model, grid, out[:, :n], out[:, n:], stats, t_failed=None if failure is None else t_reached)


class ScipyMethod(Solver):
    """One of scipy.integrate's OdeSolver classes, restarted at every force discontinuity."""

    scipy_name: ClassVar[str]
    stability_boundary: ClassVar[float] = 0.0  # on the negative real axis, explicit methods
    # The compiled right-hand side, for methods with no compiled counterpart; the scipy: cross-checks keep the
    # model's own, so that they check the kernels independently.
    compiled_rhs: ClassVar[bool] = False
    def __init__(self, breakpoints: bool = True):
        self.breakpoints = breakpoints

    def _solver_class(self):
        if self.scipy_name in OWN_SOLVERS:
            from smdcli.solvers.integrators import stiff23

            return getattr(stiff23, self.scipy_name)
        import scipy.integrate as si

        return getattr(si, self.scipy_name)

    def _attempt_counter(self):
        """A context that counts attempts, for methods whose nfev per attempt varies."""
        import scipy.integrate._ivp.bdf as bdf
        import scipy.integrate._ivp.radau as radau

        if self.scipy_name == "Radau":
            return _count_attempts(radau, "solve_collocation_system", lambda fun, t, y, h, *a: (t, h))
        if self.scipy_name == "BDF":
            return _count_attempts(bdf, "solve_bdf_system", lambda fun, t_new, y, c, *a: (t_new, c))
        return contextlib.nullcontext(None)

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        cls = self._solver_class()  # imported before the clock: wall time is the solve's own
        if self.compiled_rhs:
            warm("rhs")
        start = time.perf_counter()
        out, y, bound = _initial(model, grid)
        k = 1
        nfev = njev = nlu = accepted = attempts_rk = 0
        failure, t_reached = None, float(grid[0])
        kwargs = {"rtol": tol.rtol, "atol": tol.atol}
        if self.implicit:
            kwargs["jac"] = model.jacobian
        own = self.scipy_name in OWN_SOLVERS
        if own:
            kwargs.update(time_dependent=model.is_forced, constant_jacobian=model.is_linear)
        own_rejected = 0
        n_stages = getattr(cls, "n_stages", None)
        breakpoints = self.breakpoints and tol.breakpoints
        segs = segments(model, grid) if breakpoints else [(float(grid[0]), float(grid[-1]))]
        max_steps = tol.max_steps or MAX_STEPS
        with self._attempt_counter() as attempts_implicit:
            for ta, tb in segs:
                solver = cls((_compiled_rhs if self.compiled_rhs else _rhs)(model, ta, tb), ta, y, tb, **kwargs)
                while solver.status == "running":
                    before = solver.nfev
                    message = solver.step()
                    if n_stages:
                        attempts_rk += (solver.nfev - before) // n_stages
                    if solver.status == "failed":
                        failure = message or "step failed"
                        break
                    accepted += 1
                    if accepted > max_steps:
                        failure = f"more than {max_steps} steps"
                        break
                    t_new = solver.t
                    j = int(np.searchsorted(grid, t_new, side="right"))
                    if j > k:
                        out[k:j] = solver.dense_output()(grid[k:j]).T
                        k = j
                    failure = diverged(solver.y, bound)
                    t_reached = t_new
                    if failure:
                        break
                nfev += solver.nfev
                njev += solver.njev
                nlu += solver.nlu
                own_rejected += getattr(solver, "n_rejected", 0)
                if failure:
                    break
                y = solver.y
            if own:
                rejected = own_rejected
            elif attempts_implicit is not None:
                rejected = len(attempts_implicit) - accepted
            elif n_stages:
                rejected = attempts_rk - accepted
            else:
                rejected = -1  # LSODA does not report rejections
        if failure:
            out[k:] = np.nan
        counts = {"nfev": nfev, "njev": njev, "nlu": nlu, "steps_accepted": accepted, "steps_rejected": rejected}
        return _finish(self, model, grid, out, tol, start, counts, failure, t_reached)


class Ode113(Solver):
    """MATLAB ode113's family: variable-order Adams-Bashforth-Moulton (VODE, method='adams', never switches to BDF)."""

    order = 12
    measured_error = True  # variable order from 1, as BDF's: 3x to 7x its tolerance's statement at rtol 1e-10

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        from scipy.integrate import ode  # imported before the clock

        warm("rhs")
        start = time.perf_counter()
        out, y, bound = _initial(model, grid)
        k = 1
        counts = np.zeros(5, dtype=np.int64)  # nst, nfe, nje, nlu, rejections
        failure, t_reached = None, float(grid[0])
        for ta, tb in segments(model, grid):
            r = ode(_compiled_rhs(model, ta, tb)).set_integrator(
                "vode", method="adams", rtol=tol.rtol, atol=tol.atol, nsteps=tol.max_steps or MAX_STEPS)
            r.set_initial_value(y, ta)
            integ = r._integrator
            integ.rwork[0] = tb  # tcrit: VODE must not step past the force discontinuity
            integ.call_args[2] = 4
            stop = int(np.searchsorted(grid, tb, side="right"))
            targets = list(grid[k:stop]) + ([tb] if stop == 0 or grid[stop - 1] != tb else [])
            for target in targets:
                r.integrate(target)
                if not r.successful():
                    failure = f"VODE returned {integ.istate}"
                    break
                if k < stop and target == grid[k]:
                    out[k] = r.y
                    k += 1
                failure = diverged(r.y, bound)
                t_reached = r.t
                if failure:
                    break
            iw = integ.iwork
            counts += [iw[10], iw[11], iw[12], iw[18], iw[20] + iw[21]]
            if failure:
                break
            y = r.y.copy()
        nst, nfe, nje, nlu, rejected = (int(c) for c in counts)
        stats = {"nfev": nfe, "njev": nje, "nlu": nlu, "steps_accepted": nst, "steps_rejected": rejected}
        return _finish(self, model, grid, out, tol, start, stats, failure, t_reached)
