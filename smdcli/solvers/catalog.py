"""The solvers' names, options and option ranges as plain data: what a scenario's [solver] table may say.

The scenario layer validates against these tables without importing a solver class; the registry
owns them (tests/test_layers.py checks that they name exactly the registered solvers). Imports nothing.
"""

from __future__ import annotations

import difflib

METHOD_NAMES = ("auto", "closed_form", "exact", "RK45", "RK23", "DOP853", "taylor", "Radau", "BDF", "LSODA", "ode45", "ode23",
                "ode113", "ode15s", "ode23s", "ode23t", "ode23tb", "newmark", "sparse_newmark", "hht",
                "generalized_alpha", "central_difference", "euler", "rk4", "scipy:RK45", "scipy:RK23", "scipy:DOP853", "scipy:ode23s",
                "scipy:ode23t", "scipy:ode23tb", "scipy:Radau", "scipy:BDF")
# Parameters of the [solver] table that belong to one method each.
METHOD_OPTIONS = {"beta": "newmark", "gamma": "newmark", "scheme": "newmark", "alpha": "hht",
                  "rho_inf": "generalized_alpha"}
# Where each numeric parameter is meaningful: Newmark's beta and gamma, Hilber's alpha, Chung-Hulbert's rho_inf.
OPTION_RANGES = {"beta": (0.0, 0.5), "gamma": (0.5, 1.0), "alpha": (-1 / 3, 0.0), "rho_inf": (0.0, 1.0)}
# Newmark's named schemes: (beta, gamma).
NEWMARK_SCHEMES = {"average_acceleration": (0.25, 0.5), "linear_acceleration": (1 / 6, 0.5)}


def check_method_name(name: str) -> str | None:
    """Why a method name cannot be used, or None."""
    if name in METHOD_NAMES:
        return None
    hint = difflib.get_close_matches(name, list(METHOD_NAMES), n=1)
    extra = f" (did you mean {hint[0]!r}?)" if hint else ""
    return f"unknown method {name!r}{extra}; available: {', '.join(METHOD_NAMES)}"
