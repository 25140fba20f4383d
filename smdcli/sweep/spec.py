"""What a sweep asks for: value specs, the [sweep] table and its command-line overrides, units of swept fields.

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from smdcli.errors import ScenarioError, UsageError
from smdcli.scenario import Scenario
from smdcli.scenario.spec import GROUND_UNITS
from smdcli.scenario.units import FIELD_UNITS, UnitError, to_si
from smdcli.solvers.registry import method_problem

MAX_MEMBERS = 100_000  # values of one parameter
MAX_GRID_MEMBERS = 10_000_000  # members of a two-parameter grid (memory is checked too: see family.py)
_trapezoid = getattr(np, "trapezoid", None) or np.trapz
MAX_STACKED = 40_000_000  # samples per stacked data set (members x time points x DOFs)
METRICS = ("peak_displacement", "rms_displacement", "settling_time", "peak_ground_force", "peak_drift_ratio",
           "residual_drift")
STOREY_METRICS = ("peak_drift_ratio", "residual_drift")  # of a scene with [building]: each chain mass's storey below it
# a path's last field as the scenario reads it; a force's amplitude in N, Rayleigh's alpha and beta (damping.alpha)
_FIELD_UNITS = {**FIELD_UNITS, "amplitude": "N", "values": "N", "alpha": "1/s", "beta": "s"}


def parameter_units(path: str, scenario: Scenario | None = None) -> str:
    """The units of a swept field by its path: 'spring[0].k' -> 'N/m', 'system.K[0][1]' -> 'N/m', 'zeta' -> '1';
    an element law's keys as the law gives them (with the scenario, the element's own law: a quadratic damper's c
    is in N s^2/m^2, a Bouc-Wen spring's beta and gamma in 1/m^n)."""
    from smdcli.elements import SPRING_LAWS, TABLES

    field = re.split(r"[.\[]", path.split(".")[-1])[0] if "." in path else path
    element = re.fullmatch(r"(damper|spring|friction|stop)\[(\d+)\]\.(\w+)(\[\d+\])?", path)
    if element:
        kind, index, key = element.group(1), int(element.group(2)), element.group(3)
        tables = {"damper": "dampers", "spring": "springs", "friction": "frictions", "stop": "stops"}
        table = getattr(scenario, tables[kind]) if scenario is not None else ()
        spec = table[index] if index < len(table) else None
        if spec is not None and spec.law == "quadratic" and key == "c":
            return "N s^2/m^2"
        if spec is not None and spec.nonsmooth is not None:
            return spec.nonsmooth.unit_of(key)
        laws = SPRING_LAWS.values() if kind == "spring" else [TABLES[kind]] if kind in TABLES else []
        units = {k: unit for law in laws for k, unit in law.units.items()}
        if key in units and key not in _FIELD_UNITS:
            return units[key]
    ground = getattr(scenario, "ground_motion", None)
    if path.startswith("ground_motion.") and field in ("amplitude", "values", "shift") and ground is not None:
        return ground.units  # the table's own (units = "g"): the numbers the field holds are in it
    return _FIELD_UNITS.get(field, "")


def parameter_number(value: float | str, path: str, scenario: Scenario | None = None) -> float:
    """A parameter's value as its field holds it: a number as given; a unit string converted to the field's unit
    (SI, or a ground motion's `units`: "0.3 g" is 0.3 where the table says units = "g"). UnitError for a unit of
    another dimension."""
    if not isinstance(value, str):
        return float(value)
    ground = getattr(scenario, "ground_motion", None)
    unit = parameter_units(path, scenario) or "1"
    if ground is not None and unit == ground.units:
        sizes = GROUND_UNITS[ground.quantity]
        return to_si(value, next(u for u, f in sizes.items() if f == 1.0)) / sizes[unit]
    return to_si(value, unit)


def table_bounds(sc: Scenario, where: str, path: str, pair: tuple) -> tuple[float, float]:
    """[lower, upper] of a parameter as a scenario table gives them (numbers in SI or unit strings in the parameter's
    unit), in SI; a ScenarioError at `where` for a unit of another dimension or lower >= upper."""
    unit = parameter_units(path, sc) or "1"
    try:
        low, high = (parameter_number(v, path, sc) for v in pair)
    except UnitError as exc:
        raise ScenarioError(sc.path, where, str(exc)) from None
    if not low < high:
        raise ScenarioError(sc.path, where, f"expected [lower, upper] with lower < upper, found [{low:g}, {high:g}] "
                                            f"{unit}")
    return low, high


def parameter_label(path: str, scenario: Scenario | None = None) -> str:
    """An axis label for a swept field: 'damper[0].c [N s/m]'; Greek letters for zeta and omega."""
    units = parameter_units(path, scenario)
    shown = {"zeta": "ζ (damping ratio)"}.get(path, path.replace(".omega", ".ω"))
    return f"{shown} [{units}]" if units and units != "1" else shown


METRIC_UNITS = {"peak_displacement": "m", "rms_displacement": "m", "settling_time": "s", "peak_ground_force": "N",
                "peak_drift_ratio": "1", "residual_drift": "m"}
QUANTITIES = ("displacement", "velocity", "acceleration", "force")
DIRECTIONS = ("up", "down", "both")
SETTLING_BAND = 0.02  # settling time: the last time the response leaves 2 % of its largest excursion


# ------------------------------------------------------------------ specs


_UNIT_AFTER = re.compile(r"(.*?[\d.)])(?:\s+([^\W\d][^,:()]*|%)|\s*(%))")  # "linspace(20, 30, 5) N/mm", "1:5 %"


def parse_values(spec: Any, convert: Callable[[str], float] | None = None) -> np.ndarray:
    """Numbers from an array, "a, b, c", "start:stop:step" (stop included), "linspace(a, b, n)" or "logspace(a, b, n)".
    With `convert` (a unit string to the number the field holds), the array may hold unit strings ("20 N/mm") and a
    string may end in a unit that applies to every value ("linspace(20, 30, 5) N/mm")."""
    if isinstance(spec, (list, tuple)):
        try:
            values = np.array([convert(v) if isinstance(v, str) and convert is not None else v for v in spec],
                              dtype=float)
        except UnitError as exc:
            raise ValueError(str(exc)) from None
    else:
        text = str(spec).strip()
        written = _UNIT_AFTER.fullmatch(text) if convert is not None else None
        if written and (written.group(2) or written.group(3)):
            try:
                factor = convert(f"1 {written.group(2) or written.group(3)}")
            except UnitError as exc:
                raise ValueError(str(exc)) from None
            return parse_values(written.group(1), None) * factor
        call = re.fullmatch(r"(linspace|logspace)\s*\((.*)\)", text)
        try:
            if call:
                args = [a.strip() for a in call.group(2).split(",")]
                if len(args) != 3:
                    raise ValueError
                a, b, n = float(args[0]), float(args[1]), int(args[2])
                if not 1 <= n <= MAX_MEMBERS:
                    raise ValueError(f"{n} values; expected 1 to {MAX_MEMBERS}")
                if n < 1:
                    raise ValueError
                values = np.linspace(a, b, n) if call.group(1) == "linspace" else np.logspace(a, b, n)
            elif ":" in text:
                parts = [float(p) for p in text.split(":")]
                if len(parts) == 2:
                    parts.append(1.0)
                if len(parts) != 3:
                    raise ValueError
                start, stop, step = parts
                if step == 0 or (stop - start) * step < 0:
                    raise ValueError(f"a step of {step:g} never goes from {start:g} to {stop:g}")
                count = int(math.floor((stop - start) / step * (1 + 1e-12) + 1e-9)) + 1
                if count > MAX_MEMBERS:
                    raise ValueError(f"{count} values; at most {MAX_MEMBERS}")
                values = start + step * np.arange(count)
            else:
                values = np.array([float(p) for p in text.split(",")])
        except ValueError as exc:
            detail = f" ({exc})" if str(exc) and "could not convert" not in str(exc) and "invalid literal" not in str(exc) else ""
            raise ValueError(f"expected numbers, start:stop:step, linspace(a, b, n) or logspace(a, b, n), "
                             f"found {text[:40]!r}{detail}") from None
    if values.size == 0:
        raise ValueError("expected at least one value")
    if not np.all(np.isfinite(values)):
        raise ValueError("expected finite values")
    if values.size > MAX_MEMBERS:
        raise ValueError(f"{values.size} values; at most {MAX_MEMBERS}")
    return values


def parse_frequency(spec: Any) -> tuple[np.ndarray, str]:
    """Angular frequencies in rad/s and the unit they were given in ("rad/s" or "Hz")."""
    unit = "rad/s"
    if isinstance(spec, str):
        text = spec.strip()
        for suffix, name in (("hz", "Hz"), ("rad/s", "rad/s")):
            if text.lower().endswith(suffix):
                text, unit = text[: -len(suffix)].strip(), name
        spec = text
    values = parse_values(spec)
    if np.any(values < 0):
        raise ValueError(f"expected frequencies >= 0, found {values.min():g}")
    return (2 * math.pi * values if unit == "Hz" else values), unit


def parse_ic(text: str, dofs: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """x0 and v0 from "x0=0.1,v0=1" (one DOF) or "m1.x0=0.1,m2.v0=-1"; what is not given is zero."""
    x0, v0 = np.zeros(len(dofs)), np.zeros(len(dofs))
    for item in filter(None, (p.strip() for p in text.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip()
        dof, _, name = key.rpartition(".")
        if not sep or name not in ("x0", "v0"):
            raise ValueError(f"expected x0=VALUE, v0=VALUE or DOF.x0=VALUE, found {item!r}")
        if not dof:
            if len(dofs) != 1:
                raise ValueError(f"{len(dofs)} DOFs: name one, e.g. {dofs[0]}.{name}={value.strip()}")
            dof = dofs[0]
        if dof not in dofs:
            hint = difflib.get_close_matches(dof, dofs, n=1)
            raise ValueError(f"unknown DOF {dof!r}" + (f" (did you mean {hint[0]!r}?)" if hint else
                                                       f"; DOFs are {', '.join(dofs)}"))
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"expected a number after {key}=, found {value.strip()!r}") from None
        if not math.isfinite(number):
            raise ValueError(f"expected a finite number for {key}")
        (x0 if name == "x0" else v0)[dofs.index(dof)] = number
    return x0, v0


@dataclass(frozen=True)
class SweepSpec:
    """What to sweep and what to show, from the [sweep] table and the command line."""

    parameters: tuple[str, ...] = ()
    values: tuple[np.ndarray, ...] = ()
    labels: tuple[str, ...] = ()
    ics: tuple[str, ...] = ()
    frequency: np.ndarray | None = None
    frequency_unit: str = "rad/s"
    normalized: bool = False
    input: str | None = None
    direction: str = "both"
    measure: bool = False
    quantity: str = "displacement"
    metric: str = "peak_displacement"
    method: str | None = None

    @property
    def kind(self) -> str:
        """"frequency", "ic" or "parameter"."""
        if self.frequency is not None:
            return "frequency"
        return "ic" if self.ics else "parameter"


def read_spec(sc: Scenario, cli: dict[str, Any]) -> SweepSpec:
    """Merge the scenario's [sweep] table with command-line options (these win) and check every part."""
    table = dict(sc.sweep)

    def fail(key: str, message: str):
        if key in cli and cli[key] not in (None, (), [], False):
            return UsageError(f"--{key.replace('parameter', 'param')}: {message}")
        return ScenarioError(sc.path, f"sweep.{key}", message)

    def pick(key, default=None):
        value = cli.get(key)
        if value not in (None, (), []):
            return value
        return table.get(key, default)

    parameters = tuple(pick("parameter", ()))
    raw_values = tuple(pick("values", ()))
    if cli.get("values") in (None, (), []) and len(parameters) == 1 and len(raw_values) > 1 \
            and all(isinstance(v, str) for v in raw_values):
        raw_values = (raw_values,)  # values = ["20 N/mm", "25 N/mm"]: one parameter's values, each with its unit
    if len(parameters) != len(raw_values):
        raise fail("values", f"expected one value spec per parameter ({len(parameters)}), found {len(raw_values)}")
    if len(parameters) > 2:
        raise fail("parameter", f"expected one or two parameters, found {len(parameters)}")
    values = []
    for raw in raw_values:
        try:
            path = parameters[len(values)]
            values.append(parse_values(raw, lambda text: parameter_number(text, path, sc)))
        except ValueError as exc:
            raise fail("values", str(exc)) from None
    members = math.prod(len(v) for v in values)
    if members > MAX_GRID_MEMBERS:  # counted before any grid is made: a 100,000 x 100,000 grid is 75 GB of it
        raise fail("values", f"a grid of {' x '.join(str(len(v)) for v in values)} = {members} members; at most "
                             f"{MAX_GRID_MEMBERS}")
    labels = tuple(pick("labels", ()))
    ics = tuple(pick("ic", ()))
    frequency, unit = None, "rad/s"
    if pick("frequency") is not None:
        try:
            frequency, unit = parse_frequency(pick("frequency"))
        except ValueError as exc:
            raise fail("frequency", str(exc)) from None
    normalized = bool(pick("normalized", False))
    direction = pick("direction", "both")
    quantity = pick("quantity", "displacement")
    metric = pick("metric", "peak_displacement")
    for key, value, choices in (("direction", direction, DIRECTIONS), ("quantity", quantity, QUANTITIES),
                                ("metric", metric, METRICS)):
        if key == "metric" and value in STOREY_METRICS and sc.building is None:
            raise fail("metric", f"{value} is a storey's: it needs a [building] table (storey_heights)")
        if value not in choices:
            hint = difflib.get_close_matches(value, choices, n=1)
            raise fail(key, f"expected one of {', '.join(choices)}, found {value!r}"
                       + (f" (did you mean {hint[0]!r}?)" if hint else ""))
    if ics and parameters:
        raise fail("ic", "an initial-condition family cannot be combined with --param; sweep one or the other")
    if ics and frequency is not None:
        raise fail("ic", "a frequency response does not depend on initial conditions")
    if not ics and not parameters and frequency is None:
        raise UsageError(f"{sc.path}: nothing to sweep: give --param and --values, --ic or --frequency "
                         "(or a [sweep] table in the scenario)")
    if frequency is not None and len(parameters) > 1:
        raise fail("parameter", "a frequency response takes at most one parameter (one curve per value)")
    if labels:
        count = len(ics) if ics else (len(values[0]) if len(values) == 1 else 0)
        if len(labels) != count:
            raise fail("labels", f"expected {count} labels (one per member), found {len(labels)}")
    if normalized and frequency is None:
        raise fail("normalized", "applies to a frequency response (--frequency) only")
    if pick("method") is not None and method_problem(pick("method")):
        raise fail("method", method_problem(pick("method")))
    if frequency is not None and pick("method") is not None:
        raise fail("method", "does not apply to a frequency response: it is exact for a linear scene, "
                   "and measured with DOP853 at rtol 1e-10 otherwise")
    return SweepSpec(parameters=parameters, values=tuple(values), labels=labels, ics=ics, frequency=frequency,
                     frequency_unit=unit, normalized=normalized, input=pick("input"), direction=direction,
                     measure=bool(pick("measure", False)), quantity=quantity, metric=metric,
                     method=pick("method"))
