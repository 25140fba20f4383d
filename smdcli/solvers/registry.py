"""The one place where a method name becomes a solver.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.model import Model
from smdcli.result import Result, all_finite, finite_peak
from smdcli.solvers.base import Solver, Tolerances, stated_rounding, stated_tolerance
from smdcli.solvers.catalog import check_method_name
from smdcli.solvers.ground import across_jumps, drift_note, ground_history, record_end_note
from smdcli.solvers.nonsmooth import nonsmooth_refusal, solve_nonsmooth


@functools.cache  # one dict, built on first use: its imports are deferred for startup, not repeated per solve
def _solvers() -> dict[str, type[Solver]]:
    from smdcli.solvers.auto import Auto
    from smdcli.solvers.closed_form import ClosedForm
    from smdcli.solvers.exact import Exact
    from smdcli.solvers.sparse_newmark import SparseNewmark
    from smdcli.solvers.fixed_step import HHT, RK4, CentralDifference, Euler, GeneralizedAlpha, Newmark
    from smdcli.solvers.compiled import (BDF, DOP853, RK23, RK45, Radau, ode15s, ode23, ode23s, ode23t, ode23tb,
                                         ode45)
    from smdcli.solvers.ivp import (LSODA, Ode113, ScipyBDF, ScipyDOP853, ScipyOde23s, ScipyOde23t, ScipyOde23tb,
                                    ScipyRadau, ScipyRK23, ScipyRK45)
    from smdcli.solvers.taylor_series import Taylor

    classes = (Auto, ClosedForm, Exact, RK45, RK23, DOP853, Taylor, Radau, BDF, LSODA, ode45, ode23, Ode113, ode15s,
               ode23s, ode23t, ode23tb, Newmark, SparseNewmark, HHT, GeneralizedAlpha, CentralDifference, Euler, RK4,
               ScipyRK45, ScipyRK23, ScipyDOP853, ScipyOde23s, ScipyOde23t, ScipyOde23tb, ScipyRadau,
               ScipyBDF)
    return {cls.name: cls for cls in classes}


SPARSE_METHODS = ("auto", "sparse_newmark")  # the methods that take a sparse scene's matrices as they are


def get_solver(name: str) -> Solver:
    """A solver instance by name; raises ValueError listing the valid names."""
    problem = check_method_name(name)
    if problem:
        raise ValueError(problem)
    return _solvers()[name]()


def solve(model: Model, grid: np.ndarray, method: str, tol: Tolerances, field: str = "solver.method") -> Result:
    """Check that the method can take the model, then solve; refusals are input errors."""
    problem = check_method_name(method)
    if problem:
        raise ScenarioError(model.source, field, problem)
    solver = _solvers()[method]()
    if model.is_sparse and method not in SPARSE_METHODS:  # the others take dense matrices: n^2 memory, as asked
        model = model.dense()
    problem = nonsmooth_refusal(method, model) if model.nonsmooth else solver.refuse(model)
    if problem:
        raise ScenarioError(model.source, field, problem)
    with np.errstate(all="ignore"):  # overflow is judged below, on the result, not warned about midway
        if model.nonsmooth:  # its elements' modes and internal state carry across the ground's jumps: no restart
            result = solve_nonsmooth(solver, model, grid, tol)
        else:
            result = across_jumps(lambda piece, times: solver.solve(piece, times, tol), model, grid)
    x_extremes = result.extremes_of("displacement")  # for both checks below
    result = _refuse_non_finite(result, x_extremes)
    notes = result.notes + tuple(f"warning: {element.path}: {element.law.warning()}" for element in model.nonsmooth
                                 if element.law.warning())
    if model.ground is not None:
        history = ground_history(model, grid, solve)
        result = result.changed(ground=history)
        notes += tuple(note for note in (record_end_note(model, grid), drift_note(model, history)) if note)
    explicit = method not in ("auto", "closed_form", "exact") and not solver.implicit
    if explicit and model.is_linear and model.is_stiff:
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
    return result.changed(stats=stats, notes=notes)


def _stated_accuracy(solver: Solver, model: Model, result: Result, peak: float) -> float:
    """The error a run vouches for, relative to the peak (the largest finite |displacement|), for methods that do not
    state it themselves."""
    s = result.stats
    if solver.adaptive:
        return stated_tolerance(s.rtol, s.atol, peak)
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
