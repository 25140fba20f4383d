"""Solvers: one module a family; ``registry`` turns a name into a solver."""

from smdcli.solvers.registry import get_solver, solve

__all__ = ["get_solver", "solve"]
