"""Solvers: one module a family; ``registry`` turns a name into a solver."""

from smdcli.solvers.registry import available_methods, get_solver, solve

__all__ = ["available_methods", "get_solver", "solve"]
