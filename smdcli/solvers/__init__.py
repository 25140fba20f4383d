"""Solvers: the methods' registry (registry.py), a model solved by name (dispatch.py), a scenario run with its own
settings (run.py), `auto`'s choice (auto.py); exact/ for solutions in closed form and by the exponential, events/ for
nonsmooth scenes event to event, integrators/ for the step-by-step families.

`solve` and `get_solver` are loaded on first use, so that reading the registry imports no solver.

Must not import (at import time): any solver module.
"""


def __getattr__(name: str):
    if name == "solve":
        from smdcli.solvers.dispatch import solve

        return solve
    if name == "get_solver":
        from smdcli.solvers.registry import get_solver

        return get_solver
    raise AttributeError(name)
