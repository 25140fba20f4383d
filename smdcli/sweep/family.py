"""The members of a sweep: each the scenario with its values written into the TOML document and validated
again; members of a linear scene that differ only in structure are new matrices, interpolated.

Must not import: io, plots, commands, cli."""

from __future__ import annotations

import copy
import difflib
import math
import re
import tomllib
from dataclasses import dataclass, replace
from functools import cached_property, lru_cache
from typing import Any

import numpy as np

from smdcli import scenario as scenario_mod
from smdcli.errors import ScenarioError, UsageError
from smdcli.model import Model, build, time_grid
from smdcli.scenario import GROUND, Scenario
from smdcli.sweep.spec import SweepSpec, parameter_number, parameter_units, parse_ic

# ------------------------------------------------------------ parameters


_STEP = re.compile(r"[A-Za-z_][A-Za-z0-9_\-]*|\[\d+\]")
_OMEGA_KEYS = ("omega", "frequency", "period")


def _path_steps(path: str) -> list[str | int]:
    steps: list[str | int] = []
    for part in path.split("."):
        tokens = _STEP.findall(part)
        if not part or "".join(tokens) != part or isinstance(tokens[0], str) and tokens[0].startswith("["):
            raise UsageError(f"--param {path}: cannot read {part!r}; expected a path such as "
                             "damper[0].c, mass.m1.m or mass[0].m, force[1].omega, time.end or system.K[0][0]")
        steps.extend(int(t[1:-1]) if t.startswith("[") else t for t in tokens)
    return steps


def set_parameter(doc: dict, path: str, value: float) -> None:
    """Write one number into a decoded scenario document at a path like damper[0].c or mass.m1.m."""
    node, last, _ = _located(doc, path)
    steps = _path_steps(path)
    if isinstance(last, str) and last in _OMEGA_KEYS:
        for other in _OMEGA_KEYS:
            node.pop(other, None)
    node[last] = float(value)
    if len(steps) == 4 and steps[0] == "system" and isinstance(steps[2], int) and steps[2] != steps[3]:
        doc["system"][steps[1]][steps[3]][steps[2]] = float(value)  # keep M, C, K symmetric


def parameter_value(doc: dict, path: str, scenario: Scenario | None = None) -> float:
    """The number a decoded scenario document holds at a parameter path (an absent optional field's default: 1 for a
    scale, else 0; a force's omega, frequency or period from whichever of the three it gives; a unit string
    converted with the scenario's units, as `parameter_number` does)."""
    node, last, current = _located(doc, path)
    if isinstance(current, str):
        from smdcli.scenario.units import UnitError

        try:
            return parameter_number(current, path, scenario)
        except UnitError as exc:
            raise UsageError(f"--param {path}: {exc}") from None
    if last == "scale" and last not in node:
        return 1.0
    if isinstance(last, str) and last in _OMEGA_KEYS and last not in node:
        for given in _OMEGA_KEYS:
            value = node.get(given)
            if isinstance(value, str):
                value = parameter_number(value, f"{path.rpartition('.')[0]}.{given}", scenario)
            if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0:
                omega = value if given == "omega" else 2 * math.pi * value if given == "frequency" else \
                    2 * math.pi / value
                return {"omega": omega, "frequency": omega / (2 * math.pi)}.get(last, 2 * math.pi / omega)
    return float(current)


def is_given(doc: dict, path: str) -> bool:
    """Whether the scenario writes the number at a parameter path (not an absent optional field's default)."""
    node, last, _ = _located(doc, path)
    return isinstance(last, int) or last in node


def _located(doc: dict, path: str) -> tuple[Any, str | int, float]:
    """(the table or list holding the path's last step, that step, the number there): a UsageError naming the
    path where it leads nowhere or to something that is not a number."""
    named = re.fullmatch(r"mass\.(.+)\.(\w+)", path)
    if named and not _STEP.fullmatch(named.group(1)):  # a name a path cannot hold: 'Floor 1', '2'
        names = [t.get("name") for t in doc.get("mass", []) if isinstance(t, dict)]
        index = f"[{names.index(named.group(1))}]" if named.group(1) in names else "[i]"
        raise UsageError(f"--param {path}: the name {named.group(1)!r} cannot be written in a path; use the mass's "
                         f"index: mass{index}.{named.group(2)}")
    steps = _path_steps(path)
    node: Any = doc
    walked = ""
    for step in steps[:-1]:
        node, walked = _descend(node, step, path, walked)
    last = steps[-1]
    if isinstance(last, int):
        current = _entry(node, last, path, walked)
    else:
        if not isinstance(node, dict):
            raise UsageError(f"--param {path}: {walked or 'the file'} is not a table")
        current = node.get(last, 0.0)  # an absent optional field (x0, t0, ...); validation refuses unknown ones
    if isinstance(current, bool) or not isinstance(current, (int, float, str)) or \
            isinstance(current, str) and not current.strip()[:1] in tuple("0123456789+-."):
        raise UsageError(f"--param {path}: is not a number in the scenario (found {type(current).__name__})")
    return node, last, current


def _not_a_file(node: Any, path: str, walked: str) -> None:
    """A UsageError where a path indexes a matrix read from a file (its entries are not in the scenario)."""
    if isinstance(node, str):
        raise UsageError(f"--param {path}: {walked} is read from the file {node!r}, whose entries cannot be varied; "
                         f"write {walked} inline to vary an entry")


def _entry(node: Any, index: int, path: str, walked: str) -> Any:
    """node[index], or a UsageError saying how many entries there are."""
    _not_a_file(node, path, walked)
    if not isinstance(node, list) or index >= len(node):
        count = len(node) if isinstance(node, list) else 0
        there = f"{walked}[0] .. {walked}[{count - 1}]" if count > 1 else f"{walked}[0] only" if count else "none"
        raise UsageError(f"--param {path}: {walked} has no entry [{index}] (the scenario has {there})")
    return node[index]


def _descend(node: Any, step: str | int, path: str, walked: str) -> tuple[Any, str]:
    if isinstance(step, int):
        return _entry(node, step, path, walked), f"{walked}[{step}]"
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
# Fields a nonlinear scene's members may differ in and still be one model with other numbers: the matrices,
# the initial state and the nonlinear elements' coefficients (all affine in each field).
STRUCTURAL_NONLINEAR = re.compile(r"^(mass(\.[^.\[\]]+|\[\d+\])\.(m|x0|v0)|spring\[\d+\]\.(k|k3)"
                                  r"|damper\[\d+\]\.c)$")


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
    cubic_coef: np.ndarray | None = None  # (S, cubic elements) of a nonlinear family, else None
    quadratic_coef: np.ndarray | None = None  # (S, quadratic dampers)

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
        units = [parameter_units(p, self.scenario) for p in self.spec.parameters]
        return [", ".join(f"{name} = {v:.4g}" + (f" {unit}" if unit not in ("", "1") else "")
                          for name, unit, v in zip(names, units, combo)) for combo in self.values]

    def model(self, s: int) -> Model:
        """Member s as a Model."""
        if self.scenarios is not None:
            return build(self.scenarios[s]).dense()
        cubic, quadratic = self.base.cubic, self.base.quadratic
        if self.cubic_coef is not None:
            cubic = replace(cubic, coef=self.cubic_coef[s])
        if self.quadratic_coef is not None:
            quadratic = replace(quadratic, coef=self.quadratic_coef[s])
        return self.base.with_matrices(M=self.M[s], C=self.C[s], K=self.K[s], x0=self.x0[s], v0=self.v0[s],
                                       cubic=cubic, quadratic=quadratic)

    def output_grid(self) -> tuple[np.ndarray | None, int]:
        """The members' shared output grid (None where their grids differ, a swept time.end) and the longest
        grid's length."""
        if self.scenarios is None:
            grid = time_grid(self.scenario.time)
            return grid, len(grid)
        grids = [time_grid(sc.time) for sc in self.scenarios]
        same = all(len(g) == len(grids[0]) and np.array_equal(g, grids[0]) for g in grids)
        return (grids[0] if same else None), max(len(g) for g in grids)

    def take(self, members: range) -> Family:
        """Members start..stop as a family of their own (a chunk of a streamed sweep), not a grid."""
        part = slice(members.start, members.stop)

        def cut(a):
            return None if a is None else a[part]

        return replace(self, given_labels=self.given_labels[part], values=self.values[part], shape=(len(members),),
                       M=self.M[part], C=self.C[part], K=self.K[part], x0=self.x0[part], v0=self.v0[part],
                       scenarios=cut(self.scenarios), cubic_coef=cut(self.cubic_coef),
                       quadratic_coef=cut(self.quadratic_coef))

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


def scenario_with(sc: Scenario, values: dict[str, float]) -> Scenario:
    """The scenario with parameter paths set to values and validated again, as a member is (a fit's trial point, its
    fitted scene); a ScenarioError names the values."""
    return member_with(sc, values)[0]


def member_with(sc: Scenario, values: dict[str, float]) -> tuple[Scenario, dict, Model]:
    """scenario_with's scenario, with its TOML document and its model (built to validate it): what a search that
    visits hundreds of points would otherwise parse and build again."""
    doc = copy.deepcopy(decoded(sc.text))
    for path, value in values.items():
        set_parameter(doc, path, float(value))
    member, model = _validated_model(doc, sc, ", ".join(f"{p} = {v:.6g}" for p, v in values.items()))
    return member, doc, model


@lru_cache(maxsize=16)
def decoded(text: str) -> dict:
    """A scenario's TOML decoded once (callers copy before they edit)."""
    return tomllib.loads(text)


def _validated(doc: dict, sc: Scenario, what: str) -> Scenario:
    """A member's document as a Scenario, validated; its text is the member's own TOML."""
    return _validated_model(doc, sc, what)[0]


def _validated_model(doc: dict, sc: Scenario, what: str) -> tuple[Scenario, Model]:
    """_validated's scenario and the model it built."""
    import tomli_w

    try:
        member = scenario_mod.parse_document(doc, tomli_w.dumps(doc), sc.path)
        model = build(member)
    except ScenarioError as exc:
        raise ScenarioError(sc.path, exc.field, f"with {what}: {exc.message}") from None
    return member, model


def _coefficients(model: Model, modal: bool = False) -> dict[str, np.ndarray]:
    """The arrays a structural member differs in: matrices, initial state and nonlinear coefficients. C is the
    elements' alone where [damping] is modal: that part is not affine in M and K (modal_damped adds it)."""
    arrays = {name: getattr(model, name) for name in ("M", "C", "K", "x0", "v0")}
    if modal:
        arrays["C"] = model.C - model.added_damping
    for name in ("cubic", "quadratic"):
        if getattr(model, name) is not None:
            arrays[f"{name}_coef"] = getattr(model, name).coef
    return arrays


def structural(base: Model, paths) -> bool:
    """Whether members that differ in these paths are the base's model with other numbers, each affine in its path:
    the matrices, the initial state and a nonlinear scene's element coefficients. A hysteretic spring's k, a friction
    contact's or a stop's numbers live in its law, not in K: such a member is a scene of its own (its K interpolated
    alone left the law at the base's k, a sweep of a bilinear storey's k 300 times softer peaking at 0.0084 m where
    simulate gives 0.10 m)."""
    pattern = STRUCTURAL if base.is_linear else STRUCTURAL_NONLINEAR
    in_a_law = {element.path for element in base.nonsmooth}
    return all(pattern.match(p) and p.split(".")[0] not in in_a_law for p in paths)


def corner_span(sc: Scenario, member, low: np.ndarray, high: np.ndarray) -> tuple[dict, list[dict]]:
    """A structural box's coefficients (_coefficients) at its low corner and each parameter's change from its low to
    its high end, from members built at every corner (member(values) -> Scenario, validated): every check on a value
    is an interval, so the corners vouch for the box. ScenarioError from the corner that is not valid."""
    corners = {}
    for pick in np.ndindex(*(2,) * len(low)):
        corners[pick] = build(member(np.where(np.array(pick) == 1, high, low))).dense()
    modal = _modal(sc)
    origin = _coefficients(corners[(0,) * len(low)], modal)
    changes = []
    for i in range(len(low)):
        far = _coefficients(corners[tuple(1 if j == i else 0 for j in range(len(low)))], modal)
        changes.append({name: far[name] - origin[name] for name in origin})
    return origin, changes


def _modal(sc: Scenario) -> bool:
    """Whether [damping] is modal ratios: its C a function of the modes, not affine in M and K."""
    return sc.damping is not None and bool(sc.damping.modal)


def _modal_damped(sc: Scenario, base: Model, stacks: dict[str, np.ndarray]) -> None:
    """Each member's modal damping from its own M and K (at rest), added to its elements' interpolated C: the
    C of model.damping.added_damping, M Phi diag(2 zeta w) Phi^T M, for all members at once (M = L L^T, the modes
    from the symmetric L^-1 K L^-T)."""
    from smdcli.model.system import initial_stiffness

    K = np.stack([initial_stiffness(k, base.nonsmooth) for k in stacks["K"]]) if base.nonsmooth else stacks["K"]
    L = np.linalg.cholesky(stacks["M"])
    inner = np.linalg.solve(L, np.swapaxes(np.linalg.solve(L, K), -1, -2))
    squared, V = np.linalg.eigh(0.5 * (inner + np.swapaxes(inner, -1, -2)))
    ratios = np.broadcast_to(np.asarray(sc.damping.modal, dtype=float), squared.shape)
    left = L @ V  # M Phi with Phi = L^-T V mass-normalized
    stacks["C"] += (left * (2 * ratios * np.sqrt(np.maximum(squared, 0.0)))[:, None, :]) @ np.swapaxes(left, -1, -2)


def _stack(models: list[Model]) -> dict[str, np.ndarray]:
    return {name: np.stack([getattr(m, name) for m in models]) for name in ("M", "C", "K", "x0", "v0")}


def _check_memory(sc: Scenario, members: int, n: int) -> None:
    """Refuse, before anything is allocated, a family whose matrices and values would not fit in half of memory."""
    from smdcli.resources import fits, physical_memory

    needed = 4 * 8 * members * (3 * n * n + 4 * n + 4)  # M, C, K, x0, v0 and the grid, with working copies
    if not fits(needed):
        raise UsageError(f"{sc.path}: {members} members of {n} DOFs need about {needed / 2**30:.3g} GB for their "
                         f"matrices, more than half of this machine's {physical_memory() / 2**30:.3g} GB; sweep "
                         "fewer members")


def build_family(sc: Scenario, spec: SweepSpec) -> Family:
    """The sweep's members, validated. Structural sweeps become matrices (and a nonlinear scene's element
    coefficients) interpolated between validated corner members (every check on a value is an interval, so
    the corners vouch for the grid); anything else becomes one validated scenario per member."""
    base = build(sc).dense()  # a family's members are stacked dense
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
    _check_memory(sc, math.prod(len(v) for v in spec.values), base.n)
    grids = np.meshgrid(*spec.values, indexing="ij")
    combos = np.stack([g.ravel() for g in grids], axis=1)
    shape = tuple(len(v) for v in spec.values)
    labels = tuple(spec.labels)
    doc0 = tomllib.loads(sc.text)

    def member(combo) -> Scenario:
        doc = copy.deepcopy(doc0)
        _apply(doc, base, spec.parameters, combo)
        return _validated(doc, sc, ", ".join(f"{p} = {v:g}" for p, v in zip(spec.parameters, combo)))

    if not structural(base, spec.parameters):
        scenarios = [member(combo) for combo in combos]
        return Family(sc, spec, labels, combos, shape, base, **_stack([build(m).dense() for m in scenarios]),
                      scenarios=scenarios)
    low = np.array([v.min() for v in spec.values])
    high = np.array([v.max() for v in spec.values])
    origin, changes = corner_span(sc, member, low, high)
    stacks = {name: np.broadcast_to(value, (len(combos),) + value.shape).copy() for name, value in origin.items()}
    for i, change in enumerate(changes):
        if high[i] == low[i]:
            continue
        weight = (combos[:, i] - low[i]) / (high[i] - low[i])
        for name in stacks:
            stacks[name] += weight.reshape((-1,) + (1,) * change[name].ndim) * change[name]
    if _modal(sc):
        _modal_damped(sc, base, stacks)
    return Family(sc, spec, labels, combos, shape, base, **stacks)
