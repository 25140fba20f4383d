"""Scenes with nonsmooth elements: which method takes them, and how.

`exact` solves piecewise-linear scenes event to event (piecewise.py); the ODE family integrates any of them
event to event (nonsmooth_ivp.py); the Newmark family steps hysteretic springs by return mapping
(return_mapping.py); every other method refuses, naming the element and the methods that can.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.model import Model
from smdcli.result import Result
from smdcli.solvers.base import Solver, Tolerances


def nonsmooth_refusal(method: str, model: Model) -> str | None:
    """Why a method cannot take a scene with nonsmooth elements, naming the element and the methods that can."""
    from smdcli.solvers.nonsmooth_ivp import EVENT_METHODS
    from smdcli.solvers.return_mapping import NEWMARK_FAMILY, refusal as newmark_refusal

    if method in ("auto", "exact") or method in EVENT_METHODS:
        from smdcli.solvers.exact import Exact

        return None if method != "exact" else Exact().refuse(model)
    if method in NEWMARK_FAMILY:
        return newmark_refusal(method, model)
    first = model.nonsmooth[0]
    can = "'exact' (piecewise-linear scenes), 'auto', the ODE family ('DOP853', 'Radau', 'ode45', ...)"
    why = {"closed_form": "solves a linear 1-DOF free response only",
           "ode113": "is VODE's Adams method, which cannot be cut back to an event and restarted from Python",
           "euler": "has no interpolant to locate an event on", "rk4": "has no interpolant to locate an event on"}
    return (f"{method!r} {why.get(method, 'cannot take nonsmooth elements')}; {first.path} is {first.law.name} "
            f"({first.kind}); methods that can: {can}")


def solve_nonsmooth(solver: Solver, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
    """A scene with nonsmooth elements: exact event to event, an ODE method event to event, or the Newmark
    family's return mapping."""
    from smdcli.solvers.nonsmooth_ivp import EVENT_METHODS, solve_events
    from smdcli.solvers.return_mapping import NEWMARK_FAMILY, solve_return_mapping

    if solver.name in EVENT_METHODS:
        return solve_events(model, grid, tol, solver.name)
    if solver.name in NEWMARK_FAMILY:
        return solve_return_mapping(model, grid, tol, solver)
    return solver.solve(model, grid, tol)  # exact, auto


