"""The methods, registered once: each name with its family, its solver class, what it can take and its options.

`auto`, `compare-solvers`, the nonsmooth drivers, the JSON Schema, the command line's help and docs/solvers.md read
this table; the classes do not state their names (the registry subclasses each with its entry's name and settings).
Plain data at import (the classes are imported on first use), so the command line reads it without a solver.

Must not import (at import time): any solver module; nor sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import difflib
import functools
import importlib
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Option:
    """A parameter of the [solver] table that belongs to one method: a number in [low, high], or one of choices."""

    key: str
    low: float = 0.0
    high: float = 0.0
    choices: tuple[str, ...] = ()


@dataclass(frozen=True)
class Method:
    """One method: the name a scenario gives, where its class is, the class settings that make it this method, and
    its capabilities."""

    name: str
    family: str  # the docs' grouping: choice, exact, explicit Runge-Kutta, Taylor series, implicit, fixed step
    description: str
    solver: str  # "module:Class" under smdcli.solvers
    settings: tuple[tuple[str, Any], ...] = ()  # class attributes: a kernel's tableau, an order, a boundary
    stiff: bool = False  # stable on stiff scenes (implicit, or exact)
    events: str | None = None  # the OdeSolver formula that integrates a nonsmooth scene mode by mode, events located
    compiled_modes: tuple[str, str] | None = None  # (kernel family, tableau) running those modes compiled
    return_mapping: bool = False  # takes hysteretic scenes by the Newmark family's return mapping
    exact_events: bool = False  # takes piecewise-linear scenes exactly, event to event
    refuses_nonsmooth: str = "cannot take nonsmooth elements"  # why not, where neither of the two above
    sparse: bool = False  # takes a sparse scene's matrices as they are (the others densify)
    options: tuple[Option, ...] = ()
    compare: str | None = None  # in compare-solvers' default set: "adaptive" or "fixed"

    @property
    def nonsmooth(self) -> bool:
        """Whether the method takes scenes with nonsmooth elements (exact and auto do, event to event)."""
        return self.events is not None or self.return_mapping or self.exact_events


LOWEST_STATED_ORDER = 4  # below this order an adaptive method's global error is measured (Solver.measured_error)


def _explicit(name, tableau, order, boundary, text, compare=None):
    return Method(name, "explicit Runge-Kutta", text, "integrators.compiled:CompiledRK",
                  (("tableau", tableau), ("order", order), ("stability_boundary", boundary),
                   ("measured_error", order < LOWEST_STATED_ORDER)), events=tableau,
                  compiled_modes=("events", tableau), compare=compare)


def _stiff(name, kernel, formula, text, order=2, modes=None, compare=None):
    variable = formula == "BDF"  # orders 1-5, its lowest where it starts and wherever it drops back
    return Method(name, "implicit", text, "integrators.compiled:CompiledStiff",
                  (("kernel_method", kernel), ("order", order),
                   ("measured_error", variable or order < LOWEST_STATED_ORDER)), stiff=True, events=formula,
                  compiled_modes=modes or ("stiff", kernel), compare=compare)


def _scipy(name, formula, implicit, order, boundary, text, compiled_rhs=False, compare=None):
    measured = formula in ("BDF", "LSODA") or order < LOWEST_STATED_ORDER  # LSODA: variable order from 1
    return Method(name, "scipy.integrate (Python-driven)", text, "integrators.scipy_driven:ScipyMethod",
                  (("scipy_name", formula), ("implicit", implicit), ("order", order), ("stability_boundary", boundary),
                   ("compiled_rhs", compiled_rhs), ("measured_error", measured)), stiff=implicit, events=formula,
                  compare=compare)


_PYTHON_STIFF = "'s formula in Python on scipy's OdeSolver (smdcli.solvers.integrators.stiff23), driven from Python"
NO_INTERPOLANT = "has no interpolant to locate an event on"
OWN_SOLVERS = ("Rosenbrock23", "Trapezoid", "TRBDF2")  # formulas of smdcli.solvers.integrators.stiff23 (not scipy's)
NEWMARK_SCHEMES = {"average_acceleration": (0.25, 0.5), "linear_acceleration": (1 / 6, 0.5)}  # (beta, gamma)

METHODS = (
    Method("auto", "choice", "picks the cheapest method that is exact or accurate enough, and says why",
           "auto:Auto", stiff=True, sparse=True, exact_events=True),
    Method("closed_form", "exact", "1-DOF linear free response, all four regimes, continuous across zeta = 1",
           "exact.closed_form:ClosedForm", stiff=True, refuses_nonsmooth="solves a linear 1-DOF free response only"),
    Method("exact", "exact", "matrix exponential of the augmented state equation, exact to rounding",
           "exact.linear:Exact", stiff=True, exact_events=True),
    _explicit("RK45", "RK45", 5, 3.3, "explicit Dormand-Prince 5(4), compiled"),
    _explicit("RK23", "RK23", 3, 2.5, "explicit Bogacki-Shampine 3(2), compiled"),
    _explicit("DOP853", "DOP853", 8, 6.0, "explicit Dormand-Prince 8(5,3), compiled", compare="adaptive"),
    Method("taylor", "Taylor series", "Taylor series of order 8-30 (by the tolerance), coefficients by recurrence, "
           "compiled; for smooth scenes with forces of every shape but a frequency sweep and an expression",
           "integrators.taylor_series:Taylor", sparse=True),
    _stiff("Radau", "RADAU5", "Radau", "implicit Radau IIA, order 5, compiled (scipy's steps)", order=5,
           modes=("radau", ""), compare="adaptive"),
    _stiff("BDF", "NDF", "BDF", "implicit variable-order BDF/NDF, orders 1-5, compiled (scipy's steps)", order=5,
           modes=("bdf", "")),
    _scipy("LSODA", "LSODA", True, 12, 0.0, "ODEPACK LSODA: Adams, switching to BDF when stiff",
           compiled_rhs=True, compare="adaptive"),
    _explicit("ode45", "RK45", 5, 3.3, "MATLAB ode45's formula: Dormand-Prince 5(4), compiled", compare="adaptive"),
    _explicit("ode23", "RK23", 3, 2.5, "MATLAB ode23's formula: Bogacki-Shampine 3(2), compiled", compare="adaptive"),
    Method("ode113", "multistep", "variable-order Adams-Bashforth-Moulton PECE, orders 1-12 (VODE adams)",
           "integrators.scipy_driven:Ode113", compare="adaptive",
           refuses_nonsmooth="is VODE's Adams method, which cannot be cut back to an event and restarted from Python"),
    _stiff("ode15s", "NDF", "BDF", "MATLAB ode15s's family: variable-order NDF, orders 1-5, compiled (scipy BDF's "
           "steps)", order=5, modes=("bdf", ""), compare="adaptive"),
    _stiff("ode23s", "ROSENBROCK23", "Rosenbrock23",
           "MATLAB ode23s's formula: Rosenbrock 2(3) of Shampine and Reichelt, compiled", compare="adaptive"),
    _stiff("ode23t", "TRAPEZOID", "Trapezoid",
           "MATLAB ode23t's formula: trapezoidal rule, no numerical damping, compiled", compare="adaptive"),
    _stiff("ode23tb", "TRBDF2", "TRBDF2", "MATLAB ode23tb's formula: TR-BDF2 of Hosea and Shampine, compiled",
           compare="adaptive"),
    Method("newmark", "fixed step", "Newmark-beta, average acceleration unless beta/gamma or scheme say otherwise",
           "integrators.fixed_step:Newmark", stiff=True, return_mapping=True, compare="fixed",
           options=(Option("beta", 0.0, 0.5), Option("gamma", 0.5, 1.0), Option("scheme", choices=tuple(NEWMARK_SCHEMES)))),
    Method("sparse_newmark", "fixed step", "Newmark average acceleration on the sparse matrices, one LU reused across "
           "steps, extrapolated over steps h, h/2, h/4 to sixth order; the step made finer until its error estimate meets "
           "rtol", "integrators.sparse_newmark:SparseNewmark", stiff=True, sparse=True),
    Method("hht", "fixed step", "HHT-alpha (Hilber, Hughes, Taylor 1977), implicit, second order, damps high modes",
           "integrators.fixed_step:HilberAlpha", stiff=True, return_mapping=True, compare="fixed",
           options=(Option("alpha", -1 / 3, 0.0),)),
    Method("generalized_alpha", "fixed step", "Chung-Hulbert generalized-alpha, implicit, second order",
           "integrators.fixed_step:GeneralizedAlpha", stiff=True, return_mapping=True, compare="fixed",
           options=(Option("rho_inf", 0.0, 1.0),)),
    Method("central_difference", "fixed step", "explicit central difference (Newmark beta 0, gamma 1/2), second order, "
           "stable for h * omega_max <= 2", "integrators.fixed_step:CentralDifference", return_mapping=True,
           compare="fixed"),
    Method("euler", "fixed step", "explicit Euler on the state equation, first order (for stability studies)",
           "integrators.fixed_step:Euler", compare="fixed", refuses_nonsmooth=NO_INTERPOLANT),
    Method("rk4", "fixed step", "classic Runge-Kutta 4 on the state equation, fixed step (for stability studies)",
           "integrators.fixed_step:RK4", compare="fixed", refuses_nonsmooth=NO_INTERPOLANT),
    _scipy("scipy:RK45", "RK45", False, 5, 3.3, "scipy's RK45, Dormand-Prince 5(4), driven from Python"),
    _scipy("scipy:RK23", "RK23", False, 3, 2.5, "scipy's RK23, Bogacki-Shampine 3(2), driven from Python"),
    _scipy("scipy:DOP853", "DOP853", False, 8, 6.0, "scipy's DOP853, Dormand-Prince 8(5,3), driven from Python"),
    _scipy("scipy:ode23s", "Rosenbrock23", True, 2, 0.0, "ode23s" + _PYTHON_STIFF),
    _scipy("scipy:ode23t", "Trapezoid", True, 2, 0.0, "ode23t" + _PYTHON_STIFF),
    _scipy("scipy:ode23tb", "TRBDF2", True, 2, 0.0, "ode23tb" + _PYTHON_STIFF),
    _scipy("scipy:Radau", "Radau", True, 5, 0.0, "scipy's Radau IIA, order 5, driven from Python"),
    _scipy("scipy:BDF", "BDF", True, 5, 0.0, "scipy's variable-order BDF/NDF, orders 1-5, driven from Python"),
)
BY_NAME = {m.name: m for m in METHODS}
NAMES = tuple(BY_NAME)
OPTION_KEYS = tuple(dict.fromkeys(o.key for m in METHODS for o in m.options))  # the methods' own [solver] keys
# exact, or auto, which is exact wherever it can be: what a linear sweep's batched recurrence stands in for, and what
# compare-solvers measures the others against rather than charts
EXACT_NAMES = tuple(m.name for m in METHODS if m.family in ("choice", "exact"))


def names(*, compare: str | None = None, nonsmooth: bool | None = None) -> tuple[str, ...]:
    """The registered names, in the table's order; those in a compare-solvers group, or taking nonsmooth scenes."""
    return tuple(m.name for m in METHODS if (compare is None or m.compare == compare)
                 and (nonsmooth is None or m.nonsmooth == nonsmooth))


def method_problem(name: Any) -> str | None:
    """Why a value cannot name a method, with the nearest name; None where it does."""
    if not isinstance(name, str):
        return f"expected a method name, found {type(name).__name__} {name!r}"
    if name in BY_NAME:
        return None
    hint = difflib.get_close_matches(name, list(NAMES), n=1)
    extra = f" (did you mean {hint[0]!r}?)" if hint else ""
    return f"unknown method {name!r}{extra}; available: {', '.join(NAMES)}"


def options_problem(method: str, options: tuple[tuple[str, Any], ...]) -> tuple[str, str] | None:
    """(key, why) for the first [solver] option (one of OPTION_KEYS) that the method does not take or that is out of
    its range."""
    own = {o.key: o for o in BY_NAME[method].options}
    for key, value in options:
        if key not in own:
            owner = next(m.name for m in METHODS if any(o.key == key for o in m.options))
            return key, f"applies to method {owner!r} only, found method {method!r}"
        option = own[key]
        if option.choices:
            if value not in option.choices:
                return key, f"expected one of {', '.join(map(repr, option.choices))}, found {value!r}"
        elif isinstance(value, bool) or not isinstance(value, (int, float)) or not option.low <= value <= option.high:
            return key, f"expected a number in [{option.low:.4g}, {option.high:.4g}], found {value!r}"
    return None


@functools.cache
def solver_class(name: str) -> type:
    """The solver class of a registered name: its module's class, subclassed with the entry's name and settings."""
    method = BY_NAME[name]
    module, _, attribute = method.solver.partition(":")
    base = getattr(importlib.import_module(f"smdcli.solvers.{module}"), attribute)
    return type(name, (base,), {"name": name, "description": method.description, **dict(method.settings)})


def get_solver(name: str, **kwargs) -> Any:
    """A solver instance by name; raises ValueError listing the valid names."""
    problem = method_problem(name)
    if problem:
        raise ValueError(problem)
    return solver_class(name)(**kwargs)


def solver_options_schema() -> dict:
    """The JSON Schema of the [solver] table: the method names and each option's range or choices."""
    from smdcli.scenario.schema import NUMBER  # a number in SI or a unit string

    properties: dict[str, Any] = {"method": {"enum": list(NAMES)}, "rtol": NUMBER, "atol": NUMBER, "dt": NUMBER}
    for key in OPTION_KEYS:
        option = next(o for m in METHODS for o in m.options if o.key == key)
        properties[key] = {"enum": list(option.choices)} if option.choices else \
            {"anyOf": [{"type": "number", "minimum": option.low, "maximum": option.high}, NUMBER["anyOf"][1]]}
    return {"type": "object", "additionalProperties": False, "required": [], "properties": properties}

