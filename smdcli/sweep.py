"""smd sweep: families of runs (parameters over grids, initial conditions) and frequency responses.

A member is the scenario with one edit of its TOML document per swept parameter, validated
again like any scenario, so a value that makes a bad scene is an input error naming the field.
Linear families are solved together: one state-transition recurrence over all members at once
(see shared_signal_recurrence). Nonlinear families run in a process pool, one member per task.
"""

from __future__ import annotations

import copy
import difflib
import math
import re
import time
import tomllib
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Callable

import numpy as np

from smdcli import scenario as scenario_mod
from smdcli.errors import ScenarioError, UsageError
from smdcli.model import Model, build, time_grid
from smdcli.progress import bar
from smdcli.scenario import GROUND, Scenario

MAX_MEMBERS = 100_000
_trapezoid = getattr(np, "trapezoid", None) or np.trapz
MAX_STACKED = 40_000_000  # samples per stacked data set (members x time points x DOFs)
METRICS = ("peak_displacement", "rms_displacement", "settling_time", "peak_ground_force")
_FIELD_UNITS = {"k": "N/m", "k3": "N/m^3", "c": "N s/m", "m": "kg", "x0": "m", "v0": "m/s", "omega": "rad/s",
                "frequency": "Hz", "amplitude": "N", "t0": "s", "duration": "s", "period": "s", "t1": "s", "f0": "Hz",
                "f1": "Hz", "phase": "rad", "duty": "1", "end": "s", "start": "s", "step": "s", "zeta": "1",
                "M": "kg", "C": "N s/m", "K": "N/m"}


def parameter_units(path: str) -> str:
    """The units of a swept field by its path: 'spring[0].k' -> 'N/m', 'system.K[0][1]' -> 'N/m', 'zeta' -> '1'."""
    field = re.split(r"[.\[]", path.split(".")[-1])[0] if "." in path else path
    return _FIELD_UNITS.get(field, "")


def parameter_label(path: str) -> str:
    """An axis label for a swept field: 'damper[0].c [N s/m]'; Greek letters for zeta and omega."""
    units = parameter_units(path)
    shown = {"zeta": "ζ (damping ratio)"}.get(path, path.replace(".omega", ".ω"))
    return f"{shown} [{units}]" if units and units != "1" else shown


METRIC_UNITS = {"peak_displacement": "m", "rms_displacement": "m", "settling_time": "s", "peak_ground_force": "N"}
QUANTITIES = ("displacement", "velocity", "acceleration", "force")
DIRECTIONS = ("up", "down", "both")
SETTLING_BAND = 0.02  # settling time: the last time the response leaves 2 % of its largest excursion
EXACT_METHODS = ("auto", "exact", "closed_form")


# ------------------------------------------------------------------ specs


def parse_values(spec: Any) -> np.ndarray:
    """Numbers from an array, "a, b, c", "start:stop:step" (stop included), "linspace(a, b, n)" or "logspace(a, b, n)"."""
    if isinstance(spec, (list, tuple)):
        values = np.array(spec, dtype=float)
    else:
        text = str(spec).strip()
        call = re.fullmatch(r"(linspace|logspace)\s*\((.*)\)", text)
        try:
            if call:
                args = [a.strip() for a in call.group(2).split(",")]
                if len(args) != 3:
                    raise ValueError
                a, b, n = float(args[0]), float(args[1]), int(args[2])
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
    if len(parameters) != len(raw_values):
        raise fail("values", f"expected one value spec per parameter ({len(parameters)}), found {len(raw_values)}")
    if len(parameters) > 2:
        raise fail("parameter", f"expected one or two parameters, found {len(parameters)}")
    values = []
    for raw in raw_values:
        try:
            values.append(parse_values(raw))
        except ValueError as exc:
            raise fail("values", str(exc)) from None
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
    if frequency is not None and pick("method") is not None:
        raise fail("method", "does not apply to a frequency response: it is exact for a linear scene, "
                   "and measured with DOP853 at rtol 1e-10 otherwise")
    return SweepSpec(parameters=parameters, values=tuple(values), labels=labels, ics=ics, frequency=frequency,
                     frequency_unit=unit, normalized=normalized, input=pick("input"), direction=direction,
                     measure=bool(pick("measure", False)), quantity=quantity, metric=metric,
                     method=pick("method"))


# ------------------------------------------------------------ parameters


_STEP = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*|\[\d+\]")
_OMEGA_KEYS = ("omega", "frequency", "period")


def _path_steps(path: str) -> list[str | int]:
    steps: list[str | int] = []
    for part in path.split("."):
        tokens = _STEP.findall(part)
        if not part or "".join(tokens) != part or isinstance(tokens[0], str) and tokens[0].startswith("["):
            raise UsageError(f"--param {path}: cannot read {part!r}; expected a path such as "
                             "damper[0].c, mass.m1.m, force[1].omega, time.end or system.K[0][0]")
        steps.extend(int(t[1:-1]) if t.startswith("[") else t for t in tokens)
    return steps


def set_parameter(doc: dict, path: str, value: float) -> None:
    """Write one number into a decoded scenario document at a path like damper[0].c or mass.m1.m."""
    steps = _path_steps(path)
    node: Any = doc
    walked = ""
    for step in steps[:-1]:
        node, walked = _descend(node, step, path, walked)
    last = steps[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or last >= len(node):
            raise UsageError(f"--param {path}: {walked} has no entry [{last}]")
        current = node[last]
    else:
        if not isinstance(node, dict):
            raise UsageError(f"--param {path}: {walked or 'the file'} is not a table")
        current = node.get(last, 0.0)  # an absent optional field (x0, t0, ...); validation refuses unknown ones
        if last in _OMEGA_KEYS:
            for other in _OMEGA_KEYS:
                node.pop(other, None)
    if isinstance(current, bool) or not isinstance(current, (int, float)):
        raise UsageError(f"--param {path}: is not a number in the scenario (found {type(current).__name__})")
    node[last] = float(value)
    if len(steps) == 4 and steps[0] == "system" and isinstance(steps[2], int) and steps[2] != steps[3]:
        doc["system"][steps[1]][steps[3]][steps[2]] = float(value)  # keep M, C, K symmetric


def _descend(node: Any, step: str | int, path: str, walked: str) -> tuple[Any, str]:
    if isinstance(step, int):
        if not isinstance(node, list) or step >= len(node):
            raise UsageError(f"--param {path}: {walked} has no entry [{step}]")
        return node[step], f"{walked}[{step}]"
    if isinstance(node, list):  # mass.m1: the table of that name
        named = [t for t in node if isinstance(t, dict) and t.get("name") == step]
        if not named:
            names = [t.get("name") for t in node if isinstance(t, dict) and isinstance(t.get("name"), str)]
            hint = difflib.get_close_matches(step, names, n=1)
            raise UsageError(f"--param {path}: no {walked} named {step!r}"
                             + (f" (did you mean {hint[0]!r}?)" if hint else f"; names are {', '.join(names)}"))
        return named[0], f"{walked}.{step}"
    if not isinstance(node, dict) or step not in node:
        keys = list(node) if isinstance(node, dict) else []
        hint = difflib.get_close_matches(step, keys, n=1)
        raise UsageError(f"--param {path}: {walked or 'the file'} has no {step!r}"
                         + (f" (did you mean {hint[0]!r}?)" if hint else ""))
    return node[step], f"{walked}.{step}" if walked else step


def set_damping_ratio(doc: dict, base: Model, zeta: float, path: str) -> None:
    """The pseudo-parameter zeta of a 1-DOF scene: its linear damper gets c = 2 zeta sqrt(k m)."""
    if base.n != 1:
        raise UsageError(f"--param {path}: zeta is defined for a 1-DOF scene; this one has {base.n} DOFs")
    c = 2.0 * zeta * math.sqrt(base.K[0, 0] * base.M[0, 0])
    if "system" in doc:
        doc["system"]["C"] = [[c]]
        return
    dampers = [d for d in doc.get("damper", []) if d.get("law", "linear") == "linear"]
    if len(dampers) > 1:
        raise UsageError(f"--param {path}: zeta needs at most one linear damper; this scene has {len(dampers)}")
    if dampers:
        dampers[0]["c"] = c
    else:
        doc.setdefault("damper", []).append({"connects": [GROUND, base.dofs[0]], "c": c})


# ---------------------------------------------------------------- members

# Paths whose value enters M, C, K, x0 or v0 affinely and nothing else: members of a linear
# scene that differ only in these are new matrices, not new scenarios.
STRUCTURAL = re.compile(r"^(mass(\.[^.\[\]]+|\[\d+\])\.(m|x0|v0)|spring\[\d+\]\.k|damper\[\d+\]\.c"
                        r"|system\.[MCK]\[\d+\]\[\d+\]|system\.(x0|v0)\[\d+\]|zeta)$")


@dataclass
class Family:
    """The members of a sweep: labels, swept values and every member's matrices, stacked."""

    scenario: Scenario
    spec: SweepSpec
    given_labels: tuple[str, ...]  # legend entries given (labels, or the --ic texts); else made from values
    values: np.ndarray  # (S, number of parameters)
    shape: tuple[int, ...]  # members as a grid: one axis per parameter (or per initial condition)
    base: Model
    M: np.ndarray  # (S, n, n)
    C: np.ndarray
    K: np.ndarray
    x0: np.ndarray  # (S, n)
    v0: np.ndarray
    scenarios: list[Scenario] | None = None  # per member, where members differ in more than matrices

    def __len__(self) -> int:
        return len(self.x0)

    @cached_property
    def labels(self) -> list[str]:
        """A legend entry per member: as given, else "path = value" (made on first use: a big family rarely needs them)."""
        if self.given_labels:
            return list(self.given_labels)
        if not self.spec.parameters:
            return [self.scenario.title or self.scenario.stem]
        names = [{"zeta": "ζ"}.get(p, p.replace(".omega", ".ω")) for p in self.spec.parameters]
        units = [parameter_units(p) for p in self.spec.parameters]
        return [", ".join(f"{name} = {v:.4g}" + (f" {unit}" if unit not in ("", "1") else "")
                          for name, unit, v in zip(names, units, combo)) for combo in self.values]

    def model(self, s: int) -> Model:
        """Member s as a Model."""
        if self.scenarios is not None:
            return build(self.scenarios[s])
        return replace(self.base, M=self.M[s], C=self.C[s], K=self.K[s], x0=self.x0[s], v0=self.v0[s])

    def member_scenario(self, s: int) -> Scenario:
        """Member s as a Scenario (made on demand where the family holds only matrices)."""
        if self.scenarios is not None:
            return self.scenarios[s]
        doc = tomllib.loads(self.scenario.text)
        if self.spec.ics:
            _set_initial_state(doc, self.x0[s], self.v0[s])
        else:
            _apply(doc, self.base, self.spec.parameters, self.values[s])
        return _validated(doc, self.scenario, self.labels[s])


def _apply(doc: dict, base: Model, parameters: tuple[str, ...], combo) -> None:
    for path, value in zip(parameters, combo):
        if path == "zeta":
            set_damping_ratio(doc, base, float(value), path)
        else:
            set_parameter(doc, path, float(value))


def _set_initial_state(doc: dict, x0: np.ndarray, v0: np.ndarray) -> None:
    if "system" in doc:
        doc["system"]["x0"], doc["system"]["v0"] = x0.tolist(), v0.tolist()
    else:
        for mass, a, b in zip(doc["mass"], x0, v0):
            mass["x0"], mass["v0"] = float(a), float(b)


def _validated(doc: dict, sc: Scenario, what: str) -> Scenario:
    """A member's document as a Scenario, validated; its text is the member's own TOML."""
    import tomli_w

    try:
        member = scenario_mod.parse_document(doc, tomli_w.dumps(doc), sc.path)
        build(member)
    except ScenarioError as exc:
        raise ScenarioError(sc.path, exc.field, f"with {what}: {exc.message}") from None
    return member


def _stack(models: list[Model]) -> dict[str, np.ndarray]:
    return {name: np.stack([getattr(m, name) for m in models]) for name in ("M", "C", "K", "x0", "v0")}


def build_family(sc: Scenario, spec: SweepSpec) -> Family:
    """The sweep's members, validated. Structural sweeps of a linear scene become matrices interpolated
    between validated corner members (every check on a value is an interval, so the corners vouch for
    the grid); anything else becomes one validated scenario per member."""
    base = build(sc)
    if spec.ics:
        states = []
        for text in spec.ics:
            try:
                states.append(parse_ic(text, sc.dof_names))
            except ValueError as exc:
                raise UsageError(f"{sc.path}: ic {text!r}: {exc}") from None
        labels = tuple(spec.labels) if spec.labels else tuple(spec.ics)
        x0 = np.array([a for a, _ in states])
        v0 = np.array([b for _, b in states])
        S = len(states)
        scenarios = None
        if not base.is_linear:
            scenarios = []
            for text, a, b in zip(spec.ics, x0, v0):
                doc = tomllib.loads(sc.text)
                _set_initial_state(doc, a, b)
                scenarios.append(_validated(doc, sc, f"ic {text}"))
        return Family(sc, spec, labels, np.empty((S, 0)), (S,), base,
                      *(np.broadcast_to(getattr(base, k), (S,) + getattr(base, k).shape) for k in "MCK"),
                      x0, v0, scenarios)
    if not spec.parameters:
        stacks = _stack([base])
        return Family(sc, spec, (), np.empty((1, 0)), (1,), base, **stacks)
    if "zeta" in spec.parameters and len(spec.parameters) > 1:
        raise UsageError("--param zeta: cannot be combined with a second parameter (zeta is set from k and m)")
    grids = np.meshgrid(*spec.values, indexing="ij")
    combos = np.stack([g.ravel() for g in grids], axis=1)
    shape = tuple(len(v) for v in spec.values)
    labels = tuple(spec.labels)
    doc0 = tomllib.loads(sc.text)

    def member(combo) -> Scenario:
        doc = copy.deepcopy(doc0)
        _apply(doc, base, spec.parameters, combo)
        return _validated(doc, sc, ", ".join(f"{p} = {v:g}" for p, v in zip(spec.parameters, combo)))

    if not (base.is_linear and all(STRUCTURAL.match(p) for p in spec.parameters)):
        scenarios = [member(combo) for combo in combos]
        return Family(sc, spec, labels, combos, shape, base, **_stack([build(m) for m in scenarios]),
                      scenarios=scenarios)
    low = np.array([v.min() for v in spec.values])
    high = np.array([v.max() for v in spec.values])
    corners = {}
    for pick in np.ndindex(*(2,) * len(low)):
        corner = np.where(np.array(pick) == 1, high, low)
        corners[pick] = build(member(corner))
    origin = corners[(0,) * len(low)]
    stacks = {name: np.broadcast_to(getattr(origin, name), (len(combos),) + getattr(origin, name).shape).copy()
              for name in ("M", "C", "K", "x0", "v0")}
    for i in range(len(low)):
        if high[i] == low[i]:
            continue
        far = corners[tuple(1 if j == i else 0 for j in range(len(low)))]
        weight = (combos[:, i] - low[i]) / (high[i] - low[i])
        for name in stacks:
            delta = getattr(far, name) - getattr(origin, name)
            stacks[name] += weight.reshape((-1,) + (1,) * delta.ndim) * delta
    return Family(sc, spec, labels, combos, shape, base, **stacks)


# ------------------------------------------------------ batched linear runs


_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
           129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
           40840800.0, 960960.0, 16380.0, 182.0, 1.0)


def expm_batched(A: np.ndarray) -> np.ndarray:
    """exp(A) of a stack (S, m, m): Higham's scaling and squaring with the [13/13] Pade approximant,
    vectorized over the stack (scipy's expm costs about 9 us a matrix on the small ones a sweep has)."""
    b = _PADE13
    norm = np.abs(A).sum(axis=-2).max(initial=0.0)
    squarings = max(0, int(math.ceil(math.log2(norm / 5.371920351148152)))) if norm > 0 else 0
    A = A / 2.0**squarings
    eye = np.eye(A.shape[-1])
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye
    R = np.linalg.solve(V - U, V + U)
    for _ in range(squarings):
        R = R @ R
    return R


CHUNK = 16384  # members advanced together: long enough vectors that numpy's per-call cost is small
FORCING_BLOCK = 64  # steps whose force terms are made by one matrix product


def shared_signal_recurrence(family: Family, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, Callable[[], np.ndarray]]:
    """Displacement, velocity and acceleration (S, N, n) of a linear family whose members share their forces.

    Each member's state y = [x; v] is augmented with the force generators' state w (shared by all
    members and known in closed form at every grid time), so one output step is exactly
    y_{k+1} = Phi_yy y_k + Phi_yw w(t_k), with [Phi_yy Phi_yw] the top rows of expm(A_aug h).
    A step with a force discontinuity inside is split there. All members advance together, a chunk
    at a time; the arrays are laid out time-major (N, 2n, S) and returned as (S, N, n) views, with a
    function that derives the acceleration when it is wanted (it costs as much as the recurrence).
    """
    from smdcli.solvers.base import segments
    from smdcli.solvers.exact import augmented

    base = family.base
    n, N, S = base.n, len(grid), len(family)
    Aaug0, blocks = augmented(base)
    size = Aaug0.shape[0]
    E = size - 2 * n
    exo_block = Aaug0[2 * n:, 2 * n:]
    g_rows = np.zeros((len(base.signals), E))  # how each signal's generator state makes its value
    for j, (lo, hi, signal) in enumerate(blocks):
        g_rows[j, lo - 2 * n:hi - 2 * n] = signal.exo().g

    def exo_state(t: float) -> np.ndarray:
        return np.concatenate([signal.exo_state(t) for _, _, signal in blocks]) if blocks else np.zeros(0)

    W = np.array([exo_state(t) for t in grid]).reshape(N, E)
    signals = base.forces(grid).reshape(N, len(base.signals))
    split_steps: dict[int, list[float]] = {}
    for tb in [ta for ta, _ in segments(base, grid)][1:]:
        k = int(np.searchsorted(grid, tb, side="right")) - 1
        if grid[k] < tb:
            split_steps.setdefault(k, []).append(tb)
    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    uniform = N > 1 and np.allclose(np.diff(grid), h, rtol=1e-9, atol=0)
    Y = np.empty((N, 2 * n, S))  # displacement and velocity
    derivative_rows = []  # per chunk: the acceleration rows of A and M^-1 B
    for lo in range(0, S, CHUNK):
        hi = min(S, lo + CHUNK)
        c = hi - lo
        Minv = np.linalg.inv(family.M[lo:hi])
        A = np.zeros((c, size, size))
        A[:, :n, n:2 * n] = np.eye(n)
        A[:, n:2 * n, :n] = -Minv @ family.K[lo:hi]
        A[:, n:2 * n, n:2 * n] = -Minv @ family.C[lo:hi]
        A[:, 2 * n:, 2 * n:] = exo_block
        force_in = Minv @ base.B  # (c, n, signals)
        if E:
            A[:, n:2 * n, 2 * n:] = force_in @ g_rows
        ys = Y[:, :, lo:hi]
        ys[0, :n], ys[0, n:] = family.x0[lo:hi].T, family.v0[lo:hi].T
        cache: dict[float, np.ndarray] = {}

        def phi(dt: float) -> np.ndarray:
            if dt not in cache:
                cache[dt] = expm_batched(A * dt)
            return cache[dt]

        if uniform:
            step = phi(h)
            # The force's share Phi_yw w(t_k) of each step: one matrix product per block of steps, for every member.
            coupling = np.ascontiguousarray(step[:, :2 * n, 2 * n:].transpose(2, 1, 0)).reshape(E, 2 * n * c)
            forcing = np.zeros((FORCING_BLOCK, 2 * n, c))
            rows = [[np.ascontiguousarray(step[:, i, j]) for j in range(2 * n)] for i in range(2 * n)]
            term = np.empty(c)
        for k in range(N - 1):
            if uniform and k not in split_steps:
                b = k % FORCING_BLOCK
                if b == 0 and E:
                    block = W[k:k + FORCING_BLOCK]
                    np.matmul(block, coupling, out=forcing.reshape(FORCING_BLOCK, -1)[:len(block)])
                now, nxt = ys[k], ys[k + 1]
                for i in range(2 * n):
                    np.multiply(rows[i][0], now[0], out=nxt[i])
                    nxt[i] += forcing[b, i]
                    for j in range(1, 2 * n):
                        np.multiply(rows[i][j], now[j], out=term)
                        nxt[i] += term
                continue
            z = np.concatenate([ys[k].T, np.broadcast_to(W[k], (c, E))], axis=1)
            t_cur = grid[k]
            for tb in split_steps.get(k, []):
                z = np.einsum("sij,sj->si", phi(tb - t_cur), z)
                z[:, 2 * n:] = exo_state(tb)
                t_cur = tb
            ys[k + 1] = np.einsum("sij,sj->si", phi(grid[k + 1] - t_cur), z)[:, :2 * n].T
        derivative_rows.append((lo, hi, A[:, n:2 * n, :2 * n].copy(), force_in))

    def acceleration() -> np.ndarray:
        """a = -M^-1 K x - M^-1 C v + M^-1 B u, component by component over blocks of time and members."""
        out = np.empty((N, n, S))
        for lo, hi, rows_a, force_in in derivative_rows:
            term = np.empty((FORCING_BLOCK, hi - lo))
            for k in range(0, N, FORCING_BLOCK):
                steps = slice(k, min(N, k + FORCING_BLOCK))
                count = steps.stop - k
                for i in range(n):
                    acc = out[steps, i, lo:hi]
                    if len(base.signals):
                        np.matmul(signals[steps], force_in[:, i, :].T, out=term[:count])
                        acc[...] = term[:count]
                    else:
                        acc[...] = 0.0
                    for j in range(2 * n):
                        np.multiply(rows_a[:, i, j], Y[steps, j, lo:hi], out=term[:count])
                        acc += term[:count]
        return np.moveaxis(out, 2, 0)

    return np.moveaxis(Y[:, :n], 2, 0), np.moveaxis(Y[:, n:], 2, 0), acceleration


def batched_exact(models: list[Model], grid: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Displacement and velocity (S, N, n) of linear members with forces of their own (a swept force
    frequency, say) but the same breakpoints: each member's augmented system, one recurrence for all.
    None when the members' force structures or breakpoints differ."""
    from smdcli.solvers.base import segments
    from smdcli.solvers.exact import augmented

    if not all(m.is_linear and all(s.exo() is not None for s in m.signals) for m in models):
        return None
    systems = [augmented(m) for m in models]
    shapes = {(a.shape, tuple((lo, hi) for lo, hi, _ in blocks)) for a, blocks in systems}
    cuts = [segments(m, grid) for m in models]
    if len(shapes) != 1 or any(len(c) != len(cuts[0]) or not np.allclose(c, cuts[0], rtol=0, atol=1e-12)
                               for c in cuts):
        return None
    A = np.stack([a for a, _ in systems])
    S, size = A.shape[0], A.shape[1]
    n, N = models[0].n, len(grid)

    def reseed(z: np.ndarray, t: float) -> None:
        for s, (_, blocks) in enumerate(systems):
            for lo, hi, signal in blocks:
                z[s, lo:hi] = signal.exo_state(t)

    h = (grid[-1] - grid[0]) / (N - 1) if N > 1 else 0.0
    phi_h = expm_batched(A * h) if N > 1 else None
    out = np.empty((S, N, 2 * n))
    z = np.zeros((S, size))
    z[:, :n] = [m.x0 for m in models]
    z[:, n:2 * n] = [m.v0 for m in models]
    k = 0
    for index, (ta, tb) in enumerate(cuts[0]):
        last = index == len(cuts[0]) - 1
        reseed(z, ta)
        t_cur = ta
        stop = N if last else int(np.searchsorted(grid, tb, side="left"))
        while k < stop:
            dt = grid[k] - t_cur
            if dt > 0:
                phi = phi_h if abs(dt - h) <= 1e-9 * h else expm_batched(A * dt)
                z = np.einsum("sij,sj->si", phi, z)
            out[:, k] = z[:, :2 * n]
            t_cur = grid[k]
            k += 1
        if not last and tb > t_cur:
            z = np.einsum("sij,sj->si", expm_batched(A * (tb - t_cur)), z)
    return out[:, :, :n], out[:, :, n:]


# --------------------------------------------------------------- families


@dataclass
class FamilyResult:
    """Stacked results of a time-domain family: (S, N, n) arrays and per-member status."""

    time: np.ndarray  # (N,), or (S, N) padded with NaN when members have different grids
    dofs: tuple[str, ...]
    displacement: np.ndarray
    velocity: np.ndarray
    derived_acceleration: np.ndarray | Callable[[], np.ndarray]  # the array, or how to make it on demand
    force: np.ndarray
    success: np.ndarray  # (S,) bool
    messages: list[str]
    methods: list[str]
    how: str
    wall_time_s: float
    stated_accuracy: np.ndarray | None = None  # (S,) each member's vouched error relative to its peaks

    @property
    def acceleration(self) -> np.ndarray:
        """(S, N, n) acceleration, derived on first use where the batched path deferred it."""
        if callable(self.derived_acceleration):
            self.derived_acceleration = self.derived_acceleration()
        return self.derived_acceleration


def _solve_member(args: tuple[Scenario, str | None]) -> tuple:
    """Worker: solve one member with its own solver settings (or the override)."""
    from smdcli.simulate import Options, solve_scenario

    sc, method = args
    result = solve_scenario(sc, build(sc), time_grid(sc.time), Options(method=method))
    message = "ok" if result.success else f"{result.stats.message} (t = {result.t_failed:g} s)"
    return (result.time, result.displacement, result.velocity, result.acceleration, result.force,
            result.success, message, result.stats.method, result.stats.stated_accuracy)


_TICKS = None  # in a worker: where it reports finished steps of a long task (see run_pool's steps mode)


def _set_ticks(queue) -> None:
    global _TICKS
    _TICKS = queue


def _tick() -> None:
    """A worker reports one finished step of its task (a frequency of a measured response)."""
    if _TICKS is not None:
        _TICKS.put(1)


class _Inline:
    """The queue's put, for tasks run in this process: straight to the progress bar."""

    def __init__(self, progress):
        self.put = progress


def run_pool(function: Callable, tasks: list, workers: int, progress: Callable[[int], None] | None = None,
             steps: bool = False) -> list:
    """Results of function over tasks, in order: inline for one worker, else in a process pool.

    Progress advances by one per task; with steps=True the tasks report finer steps themselves
    (through _tick), passed back over a queue.
    """
    global _TICKS
    results: list = [None] * len(tasks)
    if workers <= 1 or len(tasks) <= 1:
        _TICKS = _Inline(progress) if (steps and progress) else None
        try:
            for i, task in enumerate(tasks):
                results[i] = function(task)
                if progress and not steps:
                    progress(1)
        finally:
            _TICKS = None
        return results
    import multiprocessing
    import queue as queue_mod
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    ticks = multiprocessing.get_context().Queue() if (steps and progress) else None
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), initializer=_set_ticks,
                             initargs=(ticks,)) as pool:
        futures = {pool.submit(function, task): i for i, task in enumerate(tasks)}
        pending = set(futures)
        try:
            while pending:
                done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                for future in done:
                    results[futures[future]] = future.result()
                    if progress and not steps:
                        progress(1)
                while ticks is not None:
                    try:
                        ticks.get_nowait()
                    except queue_mod.Empty:
                        break
                    progress(1)
        except BaseException:
            for future in futures:
                future.cancel()
            raise
    return results


def default_workers() -> int:
    """The number of cores this process may use."""
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def solve_family(family: Family, method: str | None = None, workers: int | None = None,
                 progress: Callable[[int], None] | None = None) -> FamilyResult:
    """Every member's time response: one batched exact recurrence when linear, else a process pool."""
    start = time.perf_counter()
    S, n = len(family), family.base.n
    scenarios = family.scenarios
    grids = [time_grid(sc.time) for sc in scenarios] if scenarios else [time_grid(family.scenario.time)]
    grid = grids[0]
    same_grid = all(len(g) == len(grid) and np.array_equal(g, grid) for g in grids)
    longest = max(len(g) for g in grids)
    if S * longest * n > MAX_STACKED:
        raise UsageError(f"{S} members x {longest} time points x {n} DOFs is more than {MAX_STACKED:.0e} samples "
                         "per data set; use fewer members or a coarser time grid")
    requested = {method} if method else {sc.solver.method for sc in (scenarios or [family.scenario])}
    exact_ok = requested <= set(EXACT_METHODS) and family.base.is_linear and same_grid
    batched = None
    if exact_ok and scenarios is None and all(s.exo() is not None for s in family.base.signals):
        x, v, acc = shared_signal_recurrence(family, grid)
        force = family.base.applied_force(grid) if family.base.is_forced else np.zeros((len(grid), n))
        batched = np.broadcast_to(force, (S,) + force.shape)
        how = f"one batched exact recurrence over {S} members"
    elif exact_ok:
        models = [family.model(s) for s in range(S)]
        batched = batched_exact(models, grid)
        how = f"one batched exact recurrence over {S} members (each with its own forces)"
        if batched is not None:
            x, v = batched
            batched = np.stack([m.applied_force(grid) if m.is_forced else np.zeros((len(grid), n)) for m in models])
            with np.errstate(all="ignore"):
                acc = np.stack([m.acceleration(x[s], v[s], batched[s]) for s, m in enumerate(models)])
    if batched is not None:
        force = batched
        if progress:
            progress(S)
        finite = np.isfinite(x).all(axis=(1, 2)) & np.isfinite(v).all(axis=(1, 2))
        messages = ["ok" if ok else "the solution is not finite (NaN or inf): the member's numbers overflow "
                    "double precision" for ok in finite]
        return FamilyResult(grid, family.base.dofs, x, v, acc, force, finite, messages,
                            ["exact"] * S, how, time.perf_counter() - start, _batched_stated(family, grid))
    workers = workers or default_workers()
    tasks = [(family.member_scenario(s), method) for s in range(S)]
    outcomes = run_pool(_solve_member, tasks, workers, progress)
    shape = (S, longest, n)
    stacks = {name: np.full(shape, np.nan) for name in QUANTITIES}
    times = np.full((S, longest), np.nan)
    for s, (t, x, v, a, f, *_rest) in enumerate(outcomes):
        times[s, :len(t)] = t
        for name, data in zip(QUANTITIES, (x, v, a, f)):
            stacks[name][s, :len(t)] = data
    how = f"process pool of {min(workers, S)} workers" if workers > 1 and S > 1 else "one process"
    return FamilyResult(grid if same_grid else times, family.base.dofs, stacks["displacement"],
                        stacks["velocity"], stacks["acceleration"], stacks["force"],
                        np.array([o[5] for o in outcomes]), [o[6] for o in outcomes], [o[7] for o in outcomes],
                        how, time.perf_counter() - start, np.array([o[8] for o in outcomes]))


def _batched_stated(family: Family, grid: np.ndarray) -> np.ndarray:
    """Rounding the batched exact recurrence vouches for, per member: 8 u N max(1, ||A h||_1) (see stated_rounding)."""
    from smdcli.solvers.base import stated_rounding

    h = float(grid[1] - grid[0]) if len(grid) > 1 else 0.0
    stiffness = np.abs(np.linalg.solve(family.M, family.K)).sum(axis=1).max(axis=-1)
    damping = 1 + np.abs(np.linalg.solve(family.M, family.C)).sum(axis=1).max(axis=-1)
    norm = np.maximum(stiffness, damping) * h
    return np.array([stated_rounding(len(grid), g) for g in norm])


def ground_force(family: Family, result: FamilyResult) -> np.ndarray:
    """Force each DOF passes to the ground through the elements tied to it, (S, N, n): with K's and C's
    row sums as the ground stiffness and damping (internal elements cancel in a row sum)."""
    x, v = result.displacement, result.velocity
    force = x * family.K.sum(axis=2)[:, None, :] + v * family.C.sum(axis=2)[:, None, :]
    if family.base.is_linear:
        return force
    for s in range(len(family)):
        model = family.model(s)
        for incidence, on_velocity in ((model.cubic, False), (model.quadratic, True)):
            for row, coef in zip(incidence.D, incidence.coef) if incidence is not None else ():
                if np.count_nonzero(row) == 1:
                    j = int(np.flatnonzero(row)[0])
                    d = row[j] * (v[s] if on_velocity else x[s])[:, j]
                    force[s, :, j] += row[j] * coef * (np.abs(d) * d if on_velocity else d**3)
    return force


def metrics(family: Family, result: FamilyResult) -> dict[str, np.ndarray]:
    """Scalar measures of each member per DOF, (S, n) each: peak and RMS displacement, 2 % settling
    time (NaN where the response has not settled by the end) and peak force passed to the ground."""
    x = result.displacement
    S, N, n = x.shape
    t = result.time if result.time.ndim == 2 else np.broadcast_to(result.time, (S, N))
    valid = np.isfinite(t)
    count = valid.sum(axis=1)
    with np.errstate(all="ignore"):
        peak = np.nanmax(np.abs(x), axis=1)
        span = np.nanmax(t, axis=1) - t[:, 0]
        rms = np.sqrt(_trapezoid(np.nan_to_num(x) ** 2, np.nan_to_num(t)[..., None], axis=1) / span[:, None]) \
            if N > 1 else np.abs(x[:, 0])
        final = x[np.arange(S), count - 1]  # (S, n)
        deviation = np.abs(x - final[:, None, :])
        band = SETTLING_BAND * np.nanmax(deviation, axis=1)
        outside = deviation > band[:, None, :]
        last_out = np.where(outside.any(axis=1), N - 1 - np.argmax(outside[:, ::-1, :], axis=1), -1)
        after = np.minimum(last_out + 1, N - 1)
        settling = np.where(last_out < 0, t[:, :1], np.take_along_axis(t, after, axis=1))
        settling = np.where(last_out >= (count[:, None] - 1) - max(1, int(SETTLING_BAND * N)), np.nan, settling)
        ground = np.nanmax(np.abs(ground_force(family, result)), axis=1)
    return {"peak_displacement": peak, "rms_displacement": rms, "settling_time": settling,
            "peak_ground_force": ground}


# ------------------------------------------------------- frequency response


@dataclass
class FrequencyResponse:
    """Steady-state amplitude per unit force and phase lag, (S, F, n) each, of every member."""

    omega: np.ndarray  # (F,) rad/s
    dofs: tuple[str, ...]
    input_dof: str
    amplitude: np.ndarray  # m/N
    phase: np.ndarray  # rad, lag of displacement behind force
    peaks: list[dict] = field(default_factory=list)
    measured: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # direction -> (amp, phase)
    steady: dict[str, np.ndarray] = field(default_factory=dict)  # direction -> (S, F) bool: settled to a period
    exact: bool = True
    difference: float | None = None  # largest |measured - exact| / max exact amplitude, linear scenes
    wall_time_s: float = 0.0


def input_index(model: Model, name: str | None, source: str) -> int:
    """The DOF a unit force acts on: the one named, else that of the first force, else the first DOF."""
    if name is None:
        return model.force_dofs[0] if model.force_dofs else 0
    if name not in model.dofs:
        hint = difflib.get_close_matches(name, model.dofs, n=1)
        raise UsageError(f"--input: unknown DOF {name!r} in {source}"
                         + (f" (did you mean {hint[0]!r}?)" if hint else f"; DOFs are {', '.join(model.dofs)}"))
    return model.dofs.index(name)


def receptance(M: np.ndarray, C: np.ndarray, K: np.ndarray, omega: np.ndarray, dof: int) -> np.ndarray:
    """H = (K - w^2 M + i w C)^-1 b for a unit force on `dof`: (S, F, n) complex, all members and frequencies at once.

    A singular dynamic stiffness (an undamped resonance hit exactly) gives an infinite amplitude.
    """
    w = omega[None, :, None, None]
    Z = K[:, None] - w**2 * M[:, None] + 1j * w * C[:, None]
    n = Z.shape[-1]
    b = np.zeros(n, complex)
    b[dof] = 1.0
    if n == 1:
        with np.errstate(divide="ignore", invalid="ignore"):
            H = 1.0 / Z[..., 0]
        return np.where(Z[..., 0] == 0, np.inf, H)
    try:
        return np.linalg.solve(Z, np.broadcast_to(b, Z.shape[:-1])[..., None])[..., 0]
    except np.linalg.LinAlgError:
        H = np.empty(Z.shape[:-1], complex)
        for index in np.ndindex(Z.shape[:2]):
            try:
                H[index] = np.linalg.solve(Z[index], b)
            except np.linalg.LinAlgError:
                H[index] = np.inf
        return H


def phase_lag(family: Family, omega: np.ndarray, H: np.ndarray) -> np.ndarray:
    """Lag of displacement behind force: for one DOF atan2(w c, k - w^2 m) in [0, pi] (the book's 9-35); unwrapped along frequency for several."""
    if H.shape[-1] == 1:
        c, k, mass = family.C[:, 0, :1], family.K[:, 0, :1], family.M[:, 0, :1]
        return np.arctan2(omega * c, k - omega**2 * mass)[..., None]
    with np.errstate(invalid="ignore"):
        lag = np.unwrap(-np.angle(H), axis=1)
    first = lag[:, :1]
    return lag - 2 * np.pi * np.round(first / (2 * np.pi))


def resonance_peaks(family: Family, omega: np.ndarray, amplitude: np.ndarray, dof: int) -> list[dict]:
    """Local maxima of every member's amplitude per DOF, refined on the exact receptance between grid neighbours."""
    from scipy.optimize import minimize_scalar

    peaks = []
    labels = family.labels
    for s in range(len(family)):
        if not np.any(family.C[s]):
            # Undamped: the peaks are poles at the natural frequencies, of unbounded amplitude.
            modes = family.model(s).modes
            for w, shape in zip(modes.natural_frequencies, modes.shapes.T):
                if omega[0] <= w <= omega[-1] and abs(shape[dof]) > 1e-12 * np.abs(shape).max():
                    for j, name in enumerate(family.base.dofs):
                        if abs(shape[j]) > 1e-12 * np.abs(shape).max():
                            peaks.append({"member": s, "label": labels[s], "dof": name, "omega": float(w),
                                          "amplitude": math.inf})
            continue
        for j, name in enumerate(family.base.dofs):
            a = amplitude[s, :, j]
            for f in range(1, len(omega) - 1):
                if not (a[f] > a[f - 1] and a[f] >= a[f + 1]):
                    continue
                if not np.isfinite(a[f]):
                    peaks.append({"member": s, "label": labels[s], "dof": name, "omega": float(omega[f]),
                                  "amplitude": math.inf})
                    continue

                def negative(w, s=s, j=j):
                    return -abs(receptance(family.M[s:s + 1], family.C[s:s + 1], family.K[s:s + 1],
                                           np.array([w]), dof)[0, 0, j])

                best = minimize_scalar(negative, bounds=(omega[f - 1], omega[f + 1]), method="bounded",
                                       options={"xatol": 1e-10 * max(omega[f], 1.0)})
                peaks.append({"member": s, "label": labels[s], "dof": name, "omega": float(best.x),
                              "amplitude": float(-best.fun)})
    return peaks


def _driving_force(sc: Scenario) -> int:
    """Index of the sine or cosine force whose frequency a measured response steps through."""
    for force in sc.forces:
        if force.type in ("sine", "cosine"):
            return force.index
    raise ScenarioError(sc.path, "force", "a measured frequency response needs a sine or cosine force to step "
                        "through the frequencies; add one (its amplitude sets the force level)")


PERIOD_SAMPLES = 256
MAX_PERIODS = 600
STEADY_RTOL = 1e-8
NEWTON_ITERATIONS = 8
WARMUP = 20  # periods integrated between Newton attempts


def _one_period(model: Model, y: np.ndarray, t0: float, period: float, variational: bool):
    """Integrate one forcing period from state y at t0 (DOP853, rtol 1e-10); with the monodromy matrix if asked."""
    from scipy.integrate import solve_ivp

    m = len(y)

    def rhs(t, state):
        u = model.forces(t)
        dy = model.rhs(t, state[:m], u)
        if not variational:
            return dy
        jac = model.jacobian(t, state[:m])
        return np.concatenate([dy, (jac @ state[m:].reshape(m, m)).ravel()])

    start = np.concatenate([y, np.eye(m).ravel()]) if variational else y
    scale = max(np.abs(y).max(), 1e-6)
    atol = np.full(len(start), 1e-13 * scale)
    if variational:
        atol[m:] = 1e-12
    sol = solve_ivp(rhs, (t0, t0 + period), start, method="DOP853", rtol=1e-10, atol=atol, dense_output=True)
    end = sol.y[:, -1]
    return end[:m], (end[m:].reshape(m, m) if variational else None), sol


def _steady_state(model: Model, y: np.ndarray, period: float) -> tuple[np.ndarray, bool, object]:
    """A stable periodic state of the forced scene near y, and the solution over its last period.

    Newton's method on the period map (shooting, with the monodromy matrix from the variational
    equation) reaches a periodic orbit in a few periods; it is kept only if its Floquet multipliers
    lie inside the unit circle, or on it for an undamped scene (an unstable orbit, the middle branch
    of a jump, is not what a test rig would show). Otherwise the scene is integrated for WARMUP
    periods, as a rig would settle, and Newton tries again from there; at most MAX_PERIODS in all.
    """
    scale = lambda v: max(np.abs(v).max(), 1e-12)  # noqa: E731
    spent = 0
    while spent < MAX_PERIODS:
        guess = y.copy()
        for _ in range(NEWTON_ITERATIONS):
            end, monodromy, sol = _one_period(model, guess, 0.0, period, variational=True)
            spent += 1
            residual = end - guess
            if np.abs(residual).max() <= STEADY_RTOL * scale(end):
                if np.abs(np.linalg.eigvals(monodromy)).max() < 1.0 + 1e-6:
                    return end, True, sol
                break
            try:
                step = np.linalg.solve(monodromy - np.eye(len(guess)), residual)
            except np.linalg.LinAlgError:
                break
            # A Newton step larger than the motion itself leaves the basin; on a stiffening spring it can
            # also make one period cost millions of steps. Settle by integration instead.
            if not np.all(np.isfinite(step)) or np.abs(step).max() > 2 * max(scale(y), scale(end)):
                break
            guess = guess - step
        for _ in range(WARMUP):
            previous = y
            y, _, sol = _one_period(model, y, 0.0, period, variational=False)
            spent += 1
            if np.abs(y - previous).max() <= STEADY_RTOL * scale(y):
                return y, True, sol
    return y, False, sol


def _measure_direction(args: tuple[Scenario, np.ndarray, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Worker: step a sine force through the frequencies in the order given, each from the last one's final state.

    At each frequency the steady state is found (see _steady_state); amplitude is (max - min) / 2
    of x over that whole period per unit force amplitude, and the phase lag is the fundamental's.
    """
    from smdcli.forcing import build_signal

    sc, omega, force_index = args
    base = build(sc)
    amplitude = np.full((len(omega), len(sc.dof_names)), np.nan)
    lag = np.full_like(amplitude, np.nan)
    steady = np.zeros(len(omega), bool)
    y = None
    for f, w in enumerate(omega):
        if w <= 0:
            _tick()
            continue
        signals = list(base.signals)
        signals[force_index] = build_signal(replace(sc.forces[force_index], omega=float(w)))
        model = replace(base, signals=tuple(signals))
        n = model.n
        if y is None:
            y = np.concatenate([model.x0, model.v0])
        period = 2 * math.pi / w
        f0 = abs(sc.forces[force_index].amplitude) or 1.0
        y, steady[f], sol = _steady_state(model, y, period)
        ts = sol.t[0] + period * np.arange(PERIOD_SAMPLES) / PERIOD_SAMPLES
        xs = sol.sol(ts)[:n].T
        amplitude[f] = (_refined_extreme(xs, +1) - _refined_extreme(xs, -1)) / 2 / f0
        rotation = np.exp(-1j * w * ts)
        x1 = xs.T @ rotation
        u1 = model.signals[force_index].value(ts) @ rotation
        lag[f] = np.mod(np.angle(u1) - np.angle(x1) + np.pi / 2, 2 * np.pi) - np.pi / 2
        _tick()
    return amplitude, lag, steady


def _refined_extreme(samples: np.ndarray, sign: int) -> np.ndarray:
    """Max (sign +1) or min (-1) per column of periodic samples, refined by a parabola through the top three."""
    values = sign * samples
    i = np.argmax(values, axis=0)
    cols = np.arange(values.shape[1])
    a, b, c = values[i - 1, cols], values[i, cols], values[(i + 1) % len(values), cols]
    denom = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        top = np.where(denom < 0, b - (a - c) ** 2 / (8 * denom), b)
    return sign * top


def frequency_response(family: Family, workers: int | None = None,
                       progress: Callable[[int], None] | None = None) -> FrequencyResponse:
    """Exact receptance of linear members; measured by simulation to steady state for nonlinear ones (or on request)."""
    start = time.perf_counter()
    spec = family.spec
    omega = spec.frequency
    base = family.base
    dof = input_index(base, spec.input, family.scenario.path)
    linear = base.is_linear
    S, F, n = len(family), len(omega), base.n
    if linear:
        H = receptance(family.M, family.C, family.K, omega, dof)
        amplitude, phase = np.abs(H), phase_lag(family, omega, H)
        peaks = resonance_peaks(family, omega, amplitude, dof)
    else:
        amplitude = phase = np.full((S, F, n), np.nan)
        peaks = []
    response = FrequencyResponse(omega, base.dofs, base.dofs[dof], amplitude, phase, peaks, exact=linear)
    if linear and not spec.measure:
        response.wall_time_s = time.perf_counter() - start
        if progress:
            progress(S)
        return response
    directions = ("up", "down") if spec.direction == "both" else (spec.direction,)
    tasks = []
    for s in range(S):
        member = family.member_scenario(s)
        index = _driving_force(member)
        for d in directions:
            tasks.append((member, omega if d == "up" else omega[::-1], index))
    outcomes = run_pool(_measure_direction, tasks, workers or default_workers(), progress, steps=True)
    for i, d in enumerate(directions):
        amp = np.stack([outcomes[s * len(directions) + i][0] for s in range(S)])
        lag = np.stack([outcomes[s * len(directions) + i][1] for s in range(S)])
        settled = np.stack([outcomes[s * len(directions) + i][2] for s in range(S)])
        if d == "down":
            amp, lag, settled = amp[:, ::-1], lag[:, ::-1], settled[:, ::-1]
        response.measured[d] = (amp, lag)
        response.steady[d] = settled
        for s in range(S):
            for j, name in enumerate(base.dofs):
                if np.isfinite(amp[s, :, j]).any():
                    f = int(np.nanargmax(amp[s, :, j]))
                    response.peaks.append({"member": s, "label": family.labels[s], "dof": name, "direction": d,
                                           "omega": float(omega[f]), "amplitude": float(amp[s, f, j])})
    if linear:
        amp = response.measured[directions[0]][0]
        ok = np.isfinite(amplitude) & np.isfinite(amp)
        response.difference = float(np.abs(amp - amplitude)[ok].max() / amplitude[ok].max())
    response.wall_time_s = time.perf_counter() - start
    return response


# ------------------------------------------------------------------- command


@dataclass
class SweepRun:
    """What one `smd sweep` did: the family, its results and the files written."""

    family: Family
    result: FamilyResult | None = None
    metrics: dict[str, np.ndarray] | None = None
    response: FrequencyResponse | None = None
    outputs: list = field(default_factory=list)


def run_and_write(path, out, cli: dict[str, Any], workers: int | None = None, plots: bool = True,
                  progress: bool = False) -> SweepRun:
    """Load, build the family, solve it, write `<stem>_sweep.h5` and the plots; input errors before any work."""
    from smdcli import io_hdf5
    from smdcli.simulate import output_folder

    sc = scenario_mod.load(path)
    spec = read_spec(sc, cli)
    family = build_family(sc, spec)
    if spec.frequency is not None:
        input_index(family.base, spec.input, sc.path)
        if spec.normalized and family.base.n != 1:
            raise UsageError(f"{sc.path}: --normalized needs a 1-DOF scene (X K / F0 against omega / omega_n); "
                             f"this one has {family.base.n} DOFs")
        if not family.base.is_linear or spec.measure:
            for s in {0, len(family) - 1}:
                _driving_force(family.member_scenario(s))
    out_dir = output_folder(out)
    run = SweepRun(family)
    measured = spec.frequency is not None and (not family.base.is_linear or spec.measure)
    total = len(family) * ((2 if spec.direction == "both" else 1) * len(spec.frequency) if measured else 1)
    label = "frequency response" if spec.frequency is not None else "sweeping"
    shown = progress and total > 1
    with bar(label, total, shown) as advance:
        tick = advance if shown else None  # None: workers need not report over a queue
        if spec.frequency is not None:
            run.response = frequency_response(family, workers, tick)
        else:
            run.result = solve_family(family, spec.method, workers, tick)
            run.metrics = metrics(family, run.result)
    took = run.response.wall_time_s if run.response else run.result.wall_time_s
    if run.result is not None:
        how = run.result.how
    elif run.response.measured:
        how = "simulated to steady state (shooting), one task per sweep direction"
    else:
        how = "exact receptance, all members at once"
    with io_hdf5.together():  # the files appear together, or none of them
        h5 = out_dir / f"{sc.stem}_sweep.h5"
        io_hdf5.write_sweep(h5, family, run.result, run.metrics, run.response, {"how": how, "wall_time_s": took})
        run.outputs.append(h5)
        if plots:
            from smdcli import plots as plotting

            title = sc.title or sc.stem
            figures = []
            if run.response is not None:
                figures.append(("frequency", plotting.frequency_figure(family, run.response, title, spec.frequency_unit,
                                                                       spec.normalized)))
            else:
                figures.append((spec.quantity, plotting.overlay_figure(family, run.result, spec.quantity, title)))
                if len(family) > 1 and spec.kind == "parameter":
                    name = "heatmap" if len(spec.parameters) == 2 else "metric"
                    figures.append((name, plotting.metric_figure(family, run.metrics[spec.metric], spec.metric,
                                                                 family.base.dofs, title)))
            for name, figure in figures:
                png = out_dir / f"{sc.stem}_sweep_{name}.png"
                plotting.save_figure(figure, png)
                run.outputs.append(png)
    return run


def summary(run: SweepRun) -> dict:
    """What a user wants to read after a sweep, as plain data."""
    family = run.family
    data: dict[str, Any] = {"scenario": family.scenario.path, "kind": family.spec.kind, "members": len(family),
                            "parameters": list(family.spec.parameters), "outputs": [str(p) for p in run.outputs]}
    if run.result is not None:
        data["how"] = run.result.how
        data["wall_time_s"] = run.result.wall_time_s
        data["failed"] = [family.labels[s] + ": " + run.result.messages[s]
                          for s in np.flatnonzero(~run.result.success)]
        metric = run.metrics[family.spec.metric]
        data["metric"] = {"name": family.spec.metric, "units": METRIC_UNITS[family.spec.metric],
                          "per_member": {family.labels[s]: dict(zip(family.base.dofs, map(float, metric[s])))
                                         for s in range(min(len(family), 50))}}
        if family.spec.metric == "settling_time":
            data["metric"]["null_means"] = "not settled within the run"
    if run.response is not None:
        r = run.response
        data["how"] = "exact receptance" if r.exact else "measured by simulation to steady state"
        data["wall_time_s"] = r.wall_time_s
        data["input_dof"] = r.input_dof
        data["peaks"] = r.peaks
        if r.difference is not None:
            data["measured_vs_exact"] = r.difference
        if r.measured:
            data["not_steady"] = {d: int((~v[:, r.omega > 0]).sum()) for d, v in r.steady.items()}
    return data


def format_summary(data: dict) -> str:
    """The summary as a few lines for the terminal."""
    lines = [f"{data['scenario']}: {data['members']} member{'s' if data['members'] != 1 else ''} "
             f"({data['kind']} sweep) in {data['wall_time_s'] * 1e3:.1f} ms, {data['how']}"]
    for failed in data.get("failed", []):
        lines.append(f"  failed: {failed}")
    if "metric" in data:
        name = data["metric"]["name"]
        for label, values in list(data["metric"]["per_member"].items())[:12]:
            unit = METRIC_UNITS[name]
            cells = ", ".join(f"{dof} = {value:.4g} {unit}" if value is not None and math.isfinite(value)
                              else f"{dof} = {'not settled' if name == 'settling_time' else 'n/a'}"
                              for dof, value in values.items())
            lines.append(f"  {label}: {name} {cells}")
        if data["members"] > 12:
            lines.append(f"  ... {data['members'] - 12} more in the HDF5 file")
    if "peaks" in data:
        lines.append(f"  resonance peaks (unit force on {data['input_dof']}): "
                     + ("none inside the frequency range" if not data["peaks"] else ""))
        for p in data["peaks"][:24]:
            amp = f"{p['amplitude']:.5g} m/N" if math.isfinite(p["amplitude"]) else "unbounded (undamped)"
            how = f" (largest measured, sweep {p['direction']}, on the grid)" if "direction" in p else ""
            who = f"{p['label']}: " if data["members"] > 1 else ""
            lines.append(f"    {who}{p['dof']} at {p['omega']:.6g} rad/s ({p['omega'] / (2 * math.pi):.5g} Hz), "
                         f"{amp}{how}")
        if len(data["peaks"]) > 24:
            lines.append(f"    ... {len(data['peaks']) - 24} more in the HDF5 file")
    if "measured_vs_exact" in data:
        lines.append(f"  simulated to steady state vs exact: largest difference {data['measured_vs_exact']:.2e} of the peak")
    for direction, count in data.get("not_steady", {}).items():
        if count:
            lines.append(f"  sweep {direction}: {count} frequencies did not settle to a period within {MAX_PERIODS} periods")
    lines.append("wrote " + ", ".join(data["outputs"]))
    return "\n".join(lines)
