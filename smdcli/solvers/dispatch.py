"""A model solved by a named method: the method's refusal, dense or sparse matrices, the nonsmooth route, the run's
checks (finite numbers, stated accuracy, the ground's history, warnings).

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.model import Model
from smdcli.result import Result, all_finite, finite_peak
from smdcli.solvers.base import Solver, Tolerances, stated_rounding, stated_tolerance
from smdcli.solvers.registry import BY_NAME, get_solver, method_problem, solver_class
from smdcli.solvers.ground import across_jumps, drift_note, ground_history, record_end_note
from smdcli.solvers.events.drivers import nonsmooth_refusal, solve_nonsmooth


def solve(model: Model, grid: np.ndarray, method: str, tol: Tolerances, field: str = "solver.method") -> Result:
    """Check that the method can take the model, then solve; refusals are input errors."""
    problem = method_problem(method)
    if problem:
        raise ScenarioError(model.source, field, problem)
    solver = get_solver(method)
    if model.is_sparse and not BY_NAME[method].sparse:  # the others take dense matrices: n^2 memory, as asked
        model = model.dense()
    problem = nonsmooth_refusal(method, model) if model.nonsmooth else solver.refuse(model)
    if problem:
        raise ScenarioError(model.source, field, problem)
    with np.errstate(all="ignore"):  # overflow is judged below, on the result, not warned about midway
        if model.nonsmooth:  # its elements' modes and internal state carry across the ground's jumps: no restart
            result = solve_nonsmooth(solver, model, grid, tol)
        else:
            def run(tol: Tolerances) -> Result:
                return across_jumps(lambda piece, times: solver.solve(piece, times, tol), model, grid)

            result = run(tol)
            if solver.measured_error and tol.balance:
                from smdcli.solvers.events.drivers import estimate_error

                result = estimate_error(run, result, tol, why=LOW_ORDER)
    x_extremes = result.extremes_of("displacement")  # for both checks below
    result = _refuse_non_finite(result, x_extremes)
    notes = result.notes + tuple(f"warning: {element.path}: {element.law.warning()}" for element in model.nonsmooth
                                 if element.law.warning())
    if model.ground is not None:
        history = ground_history(model, grid, solve)
        result = result.changed(ground=history)
        notes += tuple(note for note in (record_end_note(model, grid), drift_note(model, history)) if note)
    explicit = not BY_NAME[method].stiff
    if explicit and model.is_linear and not model.is_sparse and model.is_stiff:  # a sparse scene's spread is unknown
        notes += (f"warning: this scene is stiff (stiffness ratio {model.stiffness_ratio:.3g}); "
                  f"the explicit {method} is held to tiny steps by stability: try 'exact', 'Radau' or 'auto'",)
    stats = result.stats
    if math.isnan(stats.stated_accuracy):
        peak = finite_peak(result.displacement, x_extremes)
        stats = dataclasses.replace(stats, stated_accuracy=_stated_accuracy(get_solver(stats.method), model, result,
                                                                            peak))
    if method != "auto":
        stats = dataclasses.replace(stats, requested_method=method,
                                    reason=stats.reason or f"requested: {solver.description}")
    used = BY_NAME.get(stats.method)
    adaptive = used is not None and solver_class(used.name).adaptive and stats.rtol is not None
    interpolant = Interpolant(model, used.name, Tolerances(rtol=stats.rtol, atol=stats.atol)) if adaptive else None
    return result.changed(stats=stats, notes=notes, interpolant=interpolant)


LOW_ORDER = ("a low-order method's global error outgrows its tolerance as its steps multiply",
             "a higher-order method ('DOP853', 'Radau') or 'auto' lowers it at less cost")


class Interpolant:
    """x(t), v(t) at any times from a run's own adaptive method and tolerances: its steps do not depend on where output
    is asked for, so a run on other times is the run's own interpolant. It does not travel between processes."""

    def __init__(self, model: Model, method: str, tol: Tolerances):
        self.model, self.method, self.tol = model, method, tol

    def __call__(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        run = solve(self.model, times, self.method, self.tol)
        return run.displacement, run.velocity

    def __reduce__(self):
        return _nothing, ()


def _nothing() -> None:
    return None


def _stated_accuracy(solver: Solver, model: Model, result: Result, peak: float) -> float:
    """The error a run vouches for, relative to the peak (the largest finite |displacement|), for methods that do not
    state it themselves."""
    s = result.stats
    if solver.adaptive:
        speed = finite_peak(result.velocity, result.extremes_of("velocity"))
        return stated_tolerance(s.rtol, s.atol, peak, 2 * model.n if solver.rms_error_norm else 1, speed)
    span = float(result.time[-1] - result.time[0]) if len(result.time) > 1 else 0.0
    steps = int(span / s.dt) + 1 if s.dt else len(result.time)
    if s.dt and solver.order:  # global truncation of order p: (omega h)^p per radian, over omega * span radians
        w = model.omega_max
        return min(1.0, max((w * s.dt) ** solver.order * (1 + w * span), stated_rounding(steps)))
    return stated_rounding(steps)


def _refuse_non_finite(result, x_extremes):
    """A run that reports success but holds NaN or inf (numbers beyond double precision) is a failure (x_extremes:
    the displacement's, from Result.extremes_of)."""
    if not result.success or (all_finite(result.displacement, x_extremes)
                              and all_finite(result.velocity, result.extremes_of("velocity"))):
        return result
    state = np.concatenate([result.displacement, result.velocity], axis=1)
    bad = ~np.isfinite(state).all(axis=1)
    if not bad.any():
        return result
    t_bad = float(result.time[np.argmax(bad)])
    stats = dataclasses.replace(result.stats, success=False,
                                message=f"failed at t = {t_bad:.6g} s: the solution is not finite (NaN or inf): "
                                        "the scene's numbers overflow double precision")
    return result.changed(stats=stats, t_failed=t_bad)
