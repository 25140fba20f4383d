"""A run set up and solved: a scenario read with its [solver] table checked against the registry, solved with those
settings (or overrides), and what to say when a solver fails.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from smdcli import scenario as scenario_mod
from smdcli.errors import ScenarioError, SolverFailed, UsageError
from smdcli.model import Model, build, time_grid
from smdcli.result import Result
from smdcli.scenario import Scenario
from smdcli.solvers.base import Tolerances
from smdcli.scenario.options import SOLVER_KEYS, unknown_solver_key
from smdcli.solvers.registry import OPTION_KEYS, method_problem, options_problem


def check_solver(sc: Scenario) -> Scenario:
    """The scenario, its [solver] method and options checked against the registry (ScenarioError at the field)."""
    for key, _ in sc.solver.options:
        if key not in OPTION_KEYS:
            raise unknown_solver_key(sc.path, key, SOLVER_KEYS + OPTION_KEYS)
    problem = method_problem(sc.solver.method)
    if problem:
        raise ScenarioError(sc.path, "solver.method", problem)
    bad = options_problem(sc.solver.method, sc.solver.options)
    if bad:
        raise ScenarioError(sc.path, f"solver.{bad[0]}", bad[1])
    return sc


def load(path: str | Path) -> Scenario:
    """A scenario file read and checked whole, its [solver] table against the registry: every run's way in."""
    return check_solver(scenario_mod.load(path))


def check_overrides(method: str | None = None, rtol: float | None = None, atol: float | None = None) -> None:
    """The overrides of a scenario's [solver] (--method, --rtol, --atol, or simulate()'s arguments), checked the
    same way for the command line and the Python API: UsageError naming the option."""
    if method is not None:
        problem = method_problem(method)
        if problem:
            raise UsageError(f"--method: {problem}")
    for option, value in (("--rtol", rtol), ("--atol", atol)):
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            raise UsageError(f"{option}: expected a positive number, found {type(value).__name__} {value!r}")
        if not 0 < value < math.inf:
            raise UsageError(f"{option}: expected a positive number, found {float(value):g}")


def solve_scenario(sc: Scenario, model: Model, grid: np.ndarray, method: str | None = None,
                   rtol: float | None = None, atol: float | None = None) -> Result:
    """Solve with the scenario's [solver] settings, overridden by those given (the command line's)."""
    check_solver(sc)
    from smdcli.solvers.dispatch import solve

    check_overrides(method, rtol, atol)

    tol = Tolerances(rtol=sc.solver.rtol if rtol is None else rtol, atol=sc.solver.atol if atol is None else atol,
                     dt=sc.solver.dt, options=sc.solver.options)
    field_name = "--method" if method else "solver.method"
    method = method or sc.solver.method
    return solve(model, grid, method, tol, field=field_name)


def solve_checked(sc: Scenario, method: str | None = None) -> Result:
    """Solve a validated scenario on its own grid; a solver failure raises SolverFailed (exit 1)."""
    model, grid = build(sc), time_grid(sc.time)
    result = solve_scenario(sc, model, grid, method)
    if not result.success:
        raise SolverFailed(failure_message(sc, model, result), result=result)
    return result


def failure_message(sc: Scenario, model: Model, result: Result) -> str:
    """Which scenario failed, with what method, where and why, and what to try."""
    return f"{sc.path}: {result.stats.method} {result.stats.message}; {failure_hint(model, result)}"


def failure_hint(model: Model, result: Result) -> str:
    """What to try after a failed run."""
    from smdcli.solvers.integrators.fixed_step import FixedStep
    from smdcli.solvers.registry import get_solver

    solver = get_solver(result.stats.method)
    if "not finite" in result.stats.message:  # a solution that overflowed, not a step that went unstable
        return "check the units of the masses, springs, dampers and forces"
    fixed_step = isinstance(solver, FixedStep)
    if fixed_step and "steps" in result.stats.message:
        span = result.time[-1] - result.time[0]
        return (f"fixed step {result.stats.dt:.4g} s needs {span / result.stats.dt:.3g} steps for this run; "
                "set a larger solver.dt (or use an adaptive method)")
    if not solver.adaptive and not fixed_step:  # closed_form, exact
        return "try another method"
    if fixed_step:
        limit = solver.omega_limit()
        w_max = model.omega_max
        if w_max > 0 and limit < math.inf:
            stable = f"below {limit / w_max:.4g} s ({limit:.3g} / omega_max, omega_max = {w_max:.4g} rad/s)" \
                if limit > 0 else "nowhere on an undamped scene"
            return (f"fixed step {result.stats.dt:.4g} s: {solver.name}'s stable step is {stable}; "
                    "set a smaller solver.dt or use an implicit method")
        return "set a smaller solver.dt or use another method"
    if not solver.implicit and (model.is_stiff or "steps" in result.stats.message):
        return "the scene may be stiff: try an implicit method ('Radau', 'BDF', 'ode15s') or 'auto'"
    return "try tighter tolerances (--rtol, --atol) or another method"
