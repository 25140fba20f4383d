"""Nonsmooth element laws: one module a law (its TOML form, its tension in each mode, its events, energy and
internal state), and the registry that the scenario reader, the model and the solvers consult. Adding a law
touches its module and the registry, not the solvers.

Imports nothing of smd but errors.
"""

from smdcli.elements.base import EVENT_KINDS, Guard, Law, Piece, State
from smdcli.elements.registry import SPRING_LAWS, TABLES, law_for

__all__ = ["EVENT_KINDS", "Guard", "Law", "Piece", "SPRING_LAWS", "State", "TABLES", "law_for"]
