"""TOML scenario -> frozen, validated Scenario. Nothing numeric is computed here.

Every error names the file and the field path (``spring[2].k``); TOML syntax
errors name the line. Unknown keys are errors, with a "did you mean" where a
known key is close.
"""

from __future__ import annotations

import difflib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from smdcli.errors import ScenarioError

GROUND = "ground"
FORCE_TYPES = (
    "constant", "step", "sine", "cosine", "square", "fourier_square",
    "pulse", "chirp", "table", "expression",
)
# Output samples (time points x DOFs) one run may hold; beyond this the grid
# is refused before anything is allocated.
MAX_SAMPLES = 20_000_000
DEFAULT_POINTS = 1001


@dataclass(frozen=True)
class TimeSpec:
    """Output grid: from start to end, spaced by step, or `points` points."""

    start: float
    end: float
    step: float | None = None
    points: int | None = None


@dataclass(frozen=True)
class MassSpec:
    """A point mass [kg] with its initial displacement [m] and velocity [m/s]."""

    name: str
    m: float
    x0: float = 0.0
    v0: float = 0.0


@dataclass(frozen=True)
class ElementSpec:
    """A two-terminal spring (coef = k [N/m]) or damper (coef = c [N s/m])."""

    kind: str  # "spring" | "damper"
    index: int
    connects: tuple[str, str]
    coef: float
    law: str = "linear"  # spring: linear | cubic; damper: linear | quadratic
    k3: float = 0.0  # cubic spring coefficient [N/m^3]

    @property
    def path(self) -> str:
        """Field path of this element in the scenario file."""
        return f"{self.kind}[{self.index}]"


@dataclass(frozen=True)
class MatrixSystem:
    """The book's matrix form: M, C, K given whole."""

    dofs: tuple[str, ...]
    M: tuple[tuple[float, ...], ...]
    C: tuple[tuple[float, ...], ...]
    K: tuple[tuple[float, ...], ...]
    x0: tuple[float, ...]
    v0: tuple[float, ...]


@dataclass(frozen=True)
class ForceSpec:
    """One applied force; the fields used depend on `type` (see DESIGN.md)."""

    index: int
    on: str
    type: str
    amplitude: float = 0.0
    omega: float | None = None  # rad/s, resolved from frequency or period
    phase: float = 0.0
    t0: float = 0.0
    duration: float | None = None
    duty: float = 0.5
    terms: int | None = None
    f0: float | None = None
    f1: float | None = None
    t1: float | None = None
    t: tuple[float, ...] = ()
    values: tuple[float, ...] = ()
    interpolation: str = "linear"
    expr: str | None = None
    file: str | None = None  # a table force's file, as resolved, and its text: the result keeps a copy
    file_text: str | None = None

    @property
    def path(self) -> str:
        """Field path of this force in the scenario file."""
        return f"force[{self.index}]"


@dataclass(frozen=True)
class SolverSpec:
    """Requested method and tolerances; dt only for fixed-step methods."""

    method: str = "auto"
    rtol: float = 1e-6
    atol: float = 1e-9
    dt: float | None = None
    options: tuple[tuple[str, float | str], ...] = ()  # beta, gamma, scheme (newmark), alpha (hht), rho_inf


@dataclass(frozen=True)
class Scenario:
    """A validated scenario file, frozen; variants are made with dataclasses.replace."""

    path: str
    text: str
    time: TimeSpec
    masses: tuple[MassSpec, ...] = ()
    springs: tuple[ElementSpec, ...] = ()
    dampers: tuple[ElementSpec, ...] = ()
    system: MatrixSystem | None = None
    forces: tuple[ForceSpec, ...] = ()
    solver: SolverSpec = field(default_factory=SolverSpec)
    title: str = ""
    description: str = ""
    sweep: tuple[tuple[str, Any], ...] = ()

    @property
    def stem(self) -> str:
        """File name without folder and extension: the base of output names."""
        return Path(self.path).stem

    @property
    def dof_names(self) -> tuple[str, ...]:
        """Degree-of-freedom names in model order."""
        if self.system is not None:
            return self.system.dofs
        return tuple(m.name for m in self.masses)


# ---------------------------------------------------------------- reading


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return f"boolean {str(value).lower()}"
    if isinstance(value, int):
        return f"number {_short(value)}"
    if isinstance(value, float):
        return f"number {value!r}"
    if isinstance(value, str):
        shown = value if len(value) <= 40 else value[:37] + "..."
        return f"string {shown!r}"
    if isinstance(value, list):
        return f"array of {len(value)} items"
    if isinstance(value, dict):
        return "table"
    return type(value).__name__


MAX_INTEGER = 10**15  # any whole-number field (points, terms): beyond this is no scene, and not exact as a float


def _short(value: int) -> str:
    """An integer as text, or its size when it is long (str() of a huge int is slow, and refused past 4300 digits)."""
    if abs(value) < 10**20:
        return str(value)
    try:
        return f"an integer of {len(str(abs(value)))} digits"
    except ValueError:  # past Python's 4300-digit limit for int to str
        return f"an integer of about {int(abs(value).bit_length() * 0.30103) + 1} digits"


def _control_character(text: str, multiline: bool) -> str | None:
    """The first control character of `text` (terminal escapes, NUL...), or None."""
    allowed = "\t\n\r" if multiline else "\t"
    for char in text:
        if (ord(char) < 32 or 127 <= ord(char) < 160) and char not in allowed:
            return char
    return None


class _Table:
    """Reads the keys of one TOML table, checking each, then refuses leftovers."""

    def __init__(self, file: str, path: str, data: Any, allowed: tuple[str, ...] | None = None):
        if not isinstance(data, dict):
            raise ScenarioError(file, path, f"expected a table, found {_kind(data)}")
        self.file, self.path, self.data = file, path, data
        self.used: set[str] = set()
        if allowed is not None:  # a misspelt key is named first, before any message about what it left missing
            for key in data:
                if key not in allowed:
                    raise self.unknown(key, allowed)

    def unknown(self, key: str, allowed: tuple[str, ...]) -> ScenarioError:
        """An unknown key, with the allowed key it most likely means (by spelling, or by a word for it)."""
        hint = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
        if not hint:
            word = difflib.get_close_matches(key.lower(), _SYNONYMS, n=1, cutoff=0.75)
            hint = [_SYNONYMS[word[0]]] if word and _SYNONYMS[word[0]] in allowed else []
        extra = f" (did you mean {hint[0]!r}?)" if hint else ""
        known = f"; known keys: {', '.join(allowed)}" if allowed and not hint else ""
        return self.fail(key, f"unknown key{extra}{known}")

    def fail(self, key: str | None, message: str) -> ScenarioError:
        """An error at this table's key."""
        where = self.path if key is None else (f"{self.path}.{key}" if self.path else key)
        return ScenarioError(self.file, where, message)

    def missing(self, key: str, expected: str) -> ScenarioError:
        """A required key is absent: point at a misspelling of it if the table has one."""
        typo = difflib.get_close_matches(key, [k for k in self.data if k not in self.used], n=1, cutoff=0.6)
        if typo:
            return self.fail(typo[0], f"unknown key (did you mean {key!r}?)")
        return self.fail(key, f"required field is missing (expected {expected})")

    def has(self, key: str) -> bool:
        """Whether the key is present."""
        return key in self.data

    def raw(self, key: str) -> Any:
        """The value as TOML gave it, marked as used."""
        self.used.add(key)
        return self.data[key]

    def number(self, key: str, default: Any = ..., *, minimum: float | None = None,
               positive: bool = False) -> float:
        """A finite real number; `minimum` inclusive, `positive` strict."""
        if key not in self.data:
            if default is ...:
                raise self.missing(key, "a number")
            return default
        value = self.raw(key)
        return self._check_number(key, value, minimum, positive)

    def _check_number(self, key, value, minimum, positive) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, f"expected a number, found {_kind(value)}")
        try:
            value = float(value)
        except OverflowError:  # a TOML integer literal beyond any float
            raise self.fail(key, f"expected a finite number, found {_short(value)}, too large for a float") from None
        if not math.isfinite(value):
            raise self.fail(key, f"expected a finite number, found {value}")
        if positive and value <= 0:
            raise self.fail(key, f"expected a number > 0, found {value:g}")
        if minimum is not None and value < minimum:
            raise self.fail(key, f"expected a number >= {minimum:g}, found {value:g}")
        return value

    def integer(self, key: str, default: Any = ..., *, minimum: int = 0) -> int:
        """A whole number >= minimum."""
        if key not in self.data:
            if default is ...:
                raise self.missing(key, "a whole number")
            return default
        value = self.raw(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"expected a whole number, found {_kind(value)}")
        if value < minimum:
            raise self.fail(key, f"expected a whole number >= {minimum}, found {_short(value)}")
        if value > MAX_INTEGER:
            raise self.fail(key, f"expected a whole number <= {MAX_INTEGER:.0e}, found {_short(value)}")
        return value

    def string(self, key: str, default: Any = ..., *, choices: tuple[str, ...] | None = None,
               multiline: bool = False) -> str:
        """A string without control characters (tabs and, if `multiline`, line breaks allowed), optionally one of `choices`."""
        if key not in self.data:
            if default is ...:
                raise self.missing(key, "a string")
            return default
        value = self.raw(key)
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, found {_kind(value)}")
        control = _control_character(value, multiline)
        if control is not None:
            raise self.fail(key, f"expected printable text, found the control character {control!r}")
        if choices is not None and value not in choices:
            hint = difflib.get_close_matches(value, choices, n=1)
            extra = f" (did you mean {hint[0]!r}?)" if hint else ""
            raise self.fail(key, f"expected one of {', '.join(choices)}, found {value!r}{extra}")
        return value

    def numbers(self, key: str, default: Any = ..., *, length: int | None = None,
                minimum: float | None = None) -> tuple[float, ...]:
        """An array of finite numbers, optionally of a given length."""
        if key not in self.data:
            if default is ...:
                raise self.missing(key, "an array of numbers")
            return default
        value = self.raw(key)
        if not isinstance(value, list):
            raise self.fail(key, f"expected an array of numbers, found {_kind(value)}")
        if length is not None and len(value) != length:
            raise self.fail(key, f"expected {length} numbers, found {len(value)}")
        return tuple(self._check_number(f"{key}[{i}]", v, minimum, False) for i, v in enumerate(value))

    def tables(self, key: str) -> list[Any]:
        """An array of tables (possibly empty)."""
        if key not in self.data:
            return []
        value = self.raw(key)
        if not isinstance(value, list):
            raise self.fail(key, f"expected an array of tables ([[{key}]]), found {_kind(value)}")
        return value

    def finish(self, allowed: tuple[str, ...] | None = None) -> None:
        """Refuse keys nobody read, suggesting the nearest allowed key."""
        for key in self.data:
            if key not in self.used:
                raise self.unknown(key, allowed if allowed is not None else tuple(self.used))


# Words users write for a key, and the key they mean (found by spelling: "stifness" finds "stiffness").
_SYNONYMS = {"stiffness": "k", "spring_constant": "k", "spring_rate": "k", "damping": "c",
             "damping_coefficient": "c", "viscous_damping": "c", "mass": "m", "weight": "m",
             "displacement": "x0", "initial_displacement": "x0", "position": "x0", "velocity": "v0",
             "initial_velocity": "v0", "speed": "v0", "amp": "amplitude", "magnitude": "amplitude",
             "freq": "frequency", "hz": "frequency", "angular_frequency": "omega", "w": "omega",
             "duration_s": "duration", "stop": "end", "t_end": "end", "tend": "end", "t_start": "start",
             "dt_out": "step", "solver": "method", "integrator": "method", "reltol": "rtol", "abstol": "atol",
             "nodes": "connects", "connect": "connects", "between": "connects", "target": "on", "dof": "on",
             "kind": "type", "expression": "expr", "formula": "expr"}


_TOP_KEYS = ("title", "description", "time", "mass", "spring", "damper", "system",
             "force", "solver", "sweep")
_TIME_KEYS = ("start", "end", "step", "points")
_MASS_KEYS = ("name", "m", "x0", "v0")
_SYSTEM_KEYS = ("dofs", "M", "C", "K", "x0", "v0")


def _solver_keys() -> tuple[str, ...]:
    from smdcli.solvers.registry import METHOD_OPTIONS

    return ("method", "rtol", "atol", "dt", *METHOD_OPTIONS)


MAX_SCENARIO_BYTES = 16 * 2**20
MAX_TABLE_BYTES = 256 * 2**20


class _NotRegular(Exception):
    """A path that is a device, a FIFO or a socket, or a file too large: reading it could block or exhaust memory."""


def read_regular_file(path: Path, limit: int) -> bytes:
    """The bytes of a regular file of at most `limit` bytes; never blocks on a FIFO or reads a device."""
    import os
    import stat

    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))  # a FIFO opens at once instead of waiting
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = ("a named pipe (FIFO)" if stat.S_ISFIFO(info.st_mode) else "a device"
                    if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode) else "a socket"
                    if stat.S_ISSOCK(info.st_mode) else "not a regular file")
            raise _NotRegular(f"is {kind}")
        if info.st_size > limit:
            raise _NotRegular(f"is {info.st_size / 2**20:.0f} MB, more than the {limit / 2**20:.0f} MB allowed")
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read(limit + 1)
    finally:
        os.close(fd)


def load(path: str | Path) -> Scenario:
    """Read and validate a scenario file; raises ScenarioError on any bad input."""
    path = Path(path)
    file = str(path)
    if path.is_dir():
        raise ScenarioError(file, None, "is a directory, expected a scenario .toml file")
    try:
        data = read_regular_file(path, MAX_SCENARIO_BYTES)
    except FileNotFoundError:
        raise ScenarioError(file, None, "no such file") from None
    except _NotRegular as exc:
        raise ScenarioError(file, None, f"{exc}, expected a scenario .toml file") from None
    except OSError as exc:
        raise ScenarioError(file, None, f"cannot be read: {exc.strerror}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ScenarioError(file, None, "is not UTF-8 text", line=line) from None
    return parse(text, file)


def parse(text: str, file: str = "<scenario>") -> Scenario:
    """Validate scenario text; `file` names it in messages and anchors relative paths."""
    if not text.strip():
        raise ScenarioError(file, None, "is empty; a scenario needs at least [time] and one [[mass]] or [system]")
    try:
        doc = tomllib.loads(text)
    except RecursionError:
        raise ScenarioError(file, None, "invalid TOML: arrays or tables nested too deeply") from None
    except ValueError as exc:  # Python refuses integer literals of more than 4300 digits
        raise ScenarioError(file, None, f"invalid TOML: a number literal too long ({str(exc).split(':')[0]})") from None
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        match = re.search(r"\(at line (\d+), column \d+\)", message)
        line = int(match.group(1)) if match else None
        message = re.sub(r"\s*\(at line \d+, column \d+\)", "", message)
        raise ScenarioError(file, None, f"invalid TOML: {message}", line=line) from None
    return parse_document(doc, text, file)


def parse_document(doc: dict, text: str, file: str = "<scenario>") -> Scenario:
    """Validate an already-decoded TOML document (a sweep member is one, edited)."""
    top = _Table(file, "", doc, _TOP_KEYS)
    title = top.string("title", "")
    description = top.string("description", "", multiline=True)
    time = _read_time(_Table(file, "time", top.raw("time"), _TIME_KEYS) if top.has("time") else None, file)

    if top.has("system"):
        for element in ("mass", "spring", "damper"):
            if top.has(element):
                raise ScenarioError(file, element, "cannot be combined with [system]; use one form or the other")
        system = _read_system(_Table(file, "system", top.raw("system"), _SYSTEM_KEYS))
        masses, springs, dampers = (), (), ()
        dofs = system.dofs
    else:
        system = None
        masses = _read_masses(top, file)
        dofs = tuple(m.name for m in masses)
        springs = _read_elements(top, file, "spring", dofs)
        dampers = _read_elements(top, file, "damper", dofs)

    forces = tuple(
        _read_force(_Table(file, f"force[{i}]", raw, _ANY_FORCE_KEYS), i, dofs) for i, raw in enumerate(top.tables("force"))
    )
    solver = _read_solver(_Table(file, "solver", top.raw("solver"), _solver_keys())) if top.has("solver") else SolverSpec()
    sweep = _read_sweep(_Table(file, "sweep", top.raw("sweep"), SWEEP_KEYS)) if top.has("sweep") else ()
    top.finish(_TOP_KEYS)

    if not math.isfinite(time.end - time.start):
        raise ScenarioError(file, "time.end", f"expected a time span that is a finite number, found {time.end:g} - {time.start:g}")
    # In floating point: a huge span over a small step is refused before it becomes an integer.
    n_points = time.points if time.points is not None else (time.end - time.start) / time.step * (1 + 1e-12) + 1
    if not n_points * max(len(dofs), 1) <= MAX_SAMPLES:
        key = "time.points" if time.points is not None else "time.step"
        raise ScenarioError(
            file, key,
            f"output grid of {n_points:.3g} points x {len(dofs)} DOF is too large "
            f"(limit {MAX_SAMPLES:.0e} samples); use a larger step or fewer points",
        )
    for force in forces:
        if force.type == "chirp":
            _check_chirp_resolved(file, force, time, n_points)
    return Scenario(
        path=file, text=text, time=time, masses=masses, springs=springs, dampers=dampers,
        system=system, forces=forces, solver=solver, title=title, description=description,
        sweep=sweep,
    )


def _check_chirp_resolved(file: str, force: ForceSpec, time: TimeSpec, n_points: float) -> None:
    """A chirp whose frequency passes the output grid's Nyquist frequency cannot be seen or held: refuse it."""
    rate = (force.f1 - force.f0) / force.t1
    top = max(abs(force.f0 + rate * time.start), abs(force.f0 + rate * time.end))  # Hz; it sweeps on past t1
    step = (time.end - time.start) / max(n_points - 1, 1)
    if not top * step <= 0.5:
        need = 0.5 / top if top > 0 else math.inf
        raise ScenarioError(file, f"{force.path}.f1",
                            f"the chirp reaches {top:.4g} Hz by t = {time.end:g} s, above the output grid's Nyquist "
                            f"frequency {0.5 / step:.4g} Hz (step {step:.3g} s); the force cannot be resolved: use a "
                            f"[time] step of at most {need:.3g} s, or lower f1 or t1")


def _read_time(table: _Table | None, file: str) -> TimeSpec:
    if table is None:
        raise ScenarioError(file, "time", "required table is missing (expected [time] with end = ...)")
    start = table.number("start", 0.0)
    end = table.number("end")
    if end <= start:
        raise table.fail("end", f"expected a time after start = {start:g}, found {end:g}")
    if table.has("step") and table.has("points"):
        raise table.fail("points", "give either step or points, not both")
    step = table.number("step", None, positive=True)
    points = table.integer("points", None, minimum=2)
    if step is not None and step > end - start:
        raise table.fail("step", f"expected a step no longer than end - start = {end - start:g}, found {step:g}")
    if step is None and points is None:
        points = DEFAULT_POINTS
    table.finish(_TIME_KEYS)
    return TimeSpec(start=start, end=end, step=step, points=points)


def _read_masses(top: _Table, file: str) -> tuple[MassSpec, ...]:
    raw = top.tables("mass")
    if not raw:
        raise ScenarioError(file, "mass", "no masses: give [[mass]] tables or a [system] table")
    masses, seen = [], {}
    for i, item in enumerate(raw):
        t = _Table(file, f"mass[{i}]", item, _MASS_KEYS)
        name = t.string("name")
        if not name.strip():
            raise t.fail("name", "expected a non-empty name")
        if name == GROUND:
            raise t.fail("name", f"{GROUND!r} is reserved for the fixed wall")
        if name in seen:
            raise t.fail("name", f"duplicate name {name!r} (also mass[{seen[name]}])")
        seen[name] = i
        m = t.number("m", positive=True)
        x0 = t.number("x0", 0.0)
        v0 = t.number("v0", 0.0)
        t.finish(_MASS_KEYS)
        masses.append(MassSpec(name=name, m=m, x0=x0, v0=v0))
    return tuple(masses)


def _read_elements(top: _Table, file: str, kind: str, dofs: tuple[str, ...]) -> tuple[ElementSpec, ...]:
    coef_key, laws = ("k", ("linear", "cubic")) if kind == "spring" else ("c", ("linear", "quadratic"))
    elements = []
    for i, item in enumerate(top.tables(kind)):
        t = _Table(file, f"{kind}[{i}]", item, ("connects", coef_key, "law") + (("k3",) if kind == "spring" else ()))
        connects = _read_connects(t, dofs)
        law = t.string("law", "linear", choices=laws)
        coef = t.number(coef_key, minimum=0.0)
        k3 = 0.0
        allowed = ("connects", coef_key, "law")
        if kind == "spring":
            allowed += ("k3",)
            if law == "cubic":
                k3 = t.number("k3")
            elif t.has("k3"):
                raise t.fail("k3", 'only a cubic spring has k3; set law = "cubic"')
        t.finish(allowed)
        elements.append(ElementSpec(kind=kind, index=i, connects=connects, coef=coef, law=law, k3=k3))
    return tuple(elements)


def _read_connects(t: _Table, dofs: tuple[str, ...]) -> tuple[str, str]:
    if not t.has("connects"):
        raise t.fail("connects", 'required field is missing (expected ["ground", "m1"] or ["m1", "m2"])')
    value = t.raw("connects")
    if not isinstance(value, list) or len(value) != 2 or not all(isinstance(v, str) for v in value):
        raise t.fail("connects", f"expected two node names, found {_kind(value)}")
    for node in value:
        if node != GROUND and node not in dofs:
            hint = difflib.get_close_matches(node, dofs + (GROUND,), n=1)
            extra = f" (did you mean {hint[0]!r}?)" if hint else f"; nodes are {', '.join(dofs + (GROUND,))}"
            raise t.fail("connects", f"unknown node {node!r}{extra}")
    if value[0] == value[1]:
        what = "ground to ground" if value[0] == GROUND else f"{value[0]!r} to itself"
        raise t.fail("connects", f"an element from {what} does nothing; connect two different nodes")
    return (value[0], value[1])


def _read_matrix(t: _Table, key: str, n: int) -> tuple[tuple[float, ...], ...]:
    if not t.has(key):
        raise t.fail(key, f"required field is missing (expected a {n}x{n} matrix)")
    value = t.raw(key)
    if not isinstance(value, list) or len(value) != n or not all(isinstance(r, list) for r in value):
        raise t.fail(key, f"expected a {n}x{n} matrix (one row per DOF), found {_kind(value)}")
    rows = []
    for i, row in enumerate(value):
        if len(row) != n:
            raise t.fail(f"{key}[{i}]", f"expected {n} numbers (a square matrix), found {len(row)}")
        rows.append(tuple(t._check_number(f"{key}[{i}][{j}]", v, None, False) for j, v in enumerate(row)))
    matrix = tuple(rows)
    for i in range(n):
        for j in range(i + 1, n):
            a, b = matrix[i][j], matrix[j][i]
            if abs(a - b) > 1e-12 * max(abs(a), abs(b), 1.0):
                raise t.fail(key, f"expected a symmetric matrix, found {key}[{i}][{j}] = {a:g} but {key}[{j}][{i}] = {b:g}")
    _check_definite(t, key, matrix, strict=(key == "M"))
    return matrix


def _check_definite(t: _Table, key: str, matrix, strict: bool) -> None:
    # Sylvester-free check without numpy: Cholesky (semi-definite with a small slack).
    n = len(matrix)
    scale = max((abs(v) for row in matrix for v in row), default=0.0) or 1.0
    tol = 1e-12 * scale * n
    L = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            s = matrix[i][j] - sum(L[i][k] * L[j][k] for k in range(j))
            if i == j:
                if s <= (tol if strict else -tol):
                    need = "positive definite" if strict else "positive semi-definite"
                    raise t.fail(key, f"expected a symmetric {need} matrix; pivot {i} is {s:.3g}")
                L[i][i] = math.sqrt(max(s, 0.0))
            else:
                L[i][j] = s / L[j][j] if L[j][j] > 0 else 0.0


def _read_system(t: _Table) -> MatrixSystem:
    if not t.has("dofs"):
        raise t.fail("dofs", 'required field is missing (expected names, e.g. ["x1", "x2"])')
    dofs = t.raw("dofs")
    if not isinstance(dofs, list) or not dofs or not all(isinstance(d, str) and d.strip() for d in dofs):
        raise t.fail("dofs", f"expected a non-empty array of names, found {_kind(dofs)}")
    for i, name in enumerate(dofs):
        control = _control_character(name, False)
        if control is not None:
            raise t.fail(f"dofs[{i}]", f"expected printable text, found the control character {control!r}")
    if len(set(dofs)) != len(dofs):
        raise t.fail("dofs", "duplicate DOF names")
    if GROUND in dofs:
        raise t.fail("dofs", f"{GROUND!r} is reserved for the fixed wall")
    n = len(dofs)
    M = _read_matrix(t, "M", n)
    C = _read_matrix(t, "C", n) if t.has("C") else tuple(tuple(0.0 for _ in range(n)) for _ in range(n))
    K = _read_matrix(t, "K", n)
    x0 = t.numbers("x0", (0.0,) * n, length=n)
    v0 = t.numbers("v0", (0.0,) * n, length=n)
    t.finish(_SYSTEM_KEYS)
    return MatrixSystem(dofs=tuple(dofs), M=M, C=C, K=K, x0=x0, v0=v0)


_FORCE_FIELDS = {
    "constant": ("amplitude",),
    "step": ("amplitude", "t0"),
    "sine": ("amplitude", "omega", "frequency", "phase"),
    "cosine": ("amplitude", "omega", "frequency", "phase"),
    "square": ("amplitude", "omega", "frequency", "period", "duty", "t0"),
    "fourier_square": ("amplitude", "omega", "frequency", "period", "terms", "t0"),
    "pulse": ("amplitude", "t0", "duration"),
    "chirp": ("amplitude", "f0", "f1", "t1", "phase"),
    "table": ("t", "values", "file", "interpolation"),
    "expression": ("expr",),
}
_ANY_FORCE_KEYS = ("on", "type") + tuple(dict.fromkeys(k for keys in _FORCE_FIELDS.values() for k in keys))


def _read_omega(t: _Table, allow_period: bool) -> float:
    keys = ("omega", "frequency") + (("period",) if allow_period else ())
    given = [k for k in keys if t.has(k)]
    if len(given) != 1:
        want = " or ".join(keys)
        if not given:
            raise t.fail(keys[0], f"required field is missing (expected exactly one of {want})")
        raise t.fail(given[1], f"give exactly one of {want}, found {' and '.join(given)}")
    key = given[0]
    value = t.number(key, positive=(key != "omega"), minimum=0.0)
    if key == "omega":
        return value
    if key == "frequency":
        return 2 * math.pi * value
    return 2 * math.pi / value


def _read_force(t: _Table, index: int, dofs: tuple[str, ...]) -> ForceSpec:
    on = t.string("on")
    if on not in dofs:
        hint = difflib.get_close_matches(on, dofs, n=1)
        extra = f" (did you mean {hint[0]!r}?)" if hint else f"; DOFs are {', '.join(dofs)}"
        raise t.fail("on", f"unknown DOF {on!r}{extra}")
    kind = t.string("type", choices=FORCE_TYPES)
    spec: dict[str, Any] = {"index": index, "on": on, "type": kind}
    if kind in ("constant", "step", "sine", "cosine", "square", "fourier_square", "pulse", "chirp"):
        spec["amplitude"] = t.number("amplitude")
    if kind in ("step", "square", "fourier_square", "pulse"):
        spec["t0"] = t.number("t0", 0.0)
    if kind in ("sine", "cosine"):
        spec["omega"] = _read_omega(t, allow_period=False)
        spec["phase"] = t.number("phase", 0.0)
    elif kind == "square":
        spec["omega"] = _read_omega(t, allow_period=True)
        duty = t.number("duty", 0.5)
        if not 0.0 < duty < 1.0:
            raise t.fail("duty", f"expected a fraction between 0 and 1 (exclusive), found {duty:g}")
        spec["duty"] = duty
    elif kind == "fourier_square":
        spec["omega"] = _read_omega(t, allow_period=True)
        spec["terms"] = t.integer("terms", minimum=1)
        if spec["terms"] > 10_000:
            raise t.fail("terms", f"expected at most 10000 harmonics, found {spec['terms']}")
    elif kind == "pulse":
        spec["duration"] = t.number("duration", positive=True)
    elif kind == "chirp":
        spec["f0"] = t.number("f0", minimum=0.0)
        spec["f1"] = t.number("f1", minimum=0.0)
        spec["t1"] = t.number("t1", positive=True)
        spec["phase"] = t.number("phase", 0.0)
    elif kind == "table":
        spec.update(_read_table_force(t))
    elif kind == "expression":
        from smdcli.expression import Expression, ExpressionError

        text = t.string("expr")
        try:
            Expression(text)
        except ExpressionError as exc:
            raise t.fail("expr", str(exc)) from None
        spec["expr"] = text
    t.finish(("on", "type") + _FORCE_FIELDS[kind])
    return ForceSpec(**spec)


def _read_table_force(t: _Table) -> dict[str, Any]:
    interpolation = t.string("interpolation", "linear", choices=("linear", "previous"))
    if t.has("file"):
        if t.has("t") or t.has("values"):
            raise t.fail("file", "give either file or t and values, not both")
        times, values, file, file_text = _read_csv(t, t.string("file"))
    else:
        times = t.numbers("t")
        values = t.numbers("values")
        if len(values) != len(times):
            raise t.fail("values", f"expected {len(times)} numbers (one per entry of t), found {len(values)}")
    if len(times) < 1:
        raise t.fail("t", "expected at least one point")
    for i in range(1, len(times)):
        if times[i] <= times[i - 1]:
            raise t.fail(f"t[{i}]", f"expected strictly increasing times, found {times[i]:g} after {times[i - 1]:g}")
    spec = {"t": times, "values": values, "interpolation": interpolation}
    if t.has("file"):
        spec.update(file=file, file_text=file_text)
    return spec


def _read_csv(t: _Table, name: str) -> tuple[tuple[float, ...], tuple[float, ...], str, str]:
    csv_path = Path(name)
    if not csv_path.is_absolute():
        csv_path = Path(t.file).parent / csv_path
    try:
        text = read_regular_file(csv_path, MAX_TABLE_BYTES).decode("utf-8")
    except _NotRegular as exc:
        raise t.fail("file", f"{csv_path}: {exc}, expected a CSV file") from None
    except (OSError, UnicodeDecodeError) as exc:
        reason = "no such file" if isinstance(exc, FileNotFoundError) else (
            "is a directory" if isinstance(exc, IsADirectoryError) else "cannot be read as UTF-8 text")
        raise t.fail("file", f"{csv_path}: {reason}") from None
    times, values = [], []
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        cells = [c.strip() for c in re.split(r"[,;\t]", stripped)]
        try:
            a, b = (float(c) for c in cells)
        except ValueError:
            if not times and number == 1 and len(cells) == 2:
                continue  # a header row
            raise t.fail("file", f"{csv_path} line {number}: expected two numbers (t, value), found {stripped[:40]!r}") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise t.fail("file", f"{csv_path} line {number}: expected finite numbers")
        times.append(a)
        values.append(b)
    if not times:
        raise t.fail("file", f"{csv_path}: no data rows")
    return tuple(times), tuple(values), str(csv_path), text


def _read_solver(t: _Table) -> SolverSpec:
    from smdcli.solvers.fixed_step import Newmark
    from smdcli.solvers.registry import METHOD_OPTIONS, OPTION_RANGES, check_method_name

    method = t.string("method", "auto")
    problem = check_method_name(method)
    if problem:
        raise t.fail("method", problem)
    rtol = t.number("rtol", 1e-6, positive=True)
    atol = t.number("atol", 1e-9, positive=True)
    dt = t.number("dt", None, positive=True)
    options = []
    for key, owner in METHOD_OPTIONS.items():
        if not t.has(key):
            continue
        if method != owner:
            raise t.fail(key, f"applies to method {owner!r} only, found method {method!r}")
        if key == "scheme":
            value = t.string(key)
            if value not in Newmark.SCHEMES:
                raise t.fail(key, f"expected one of {', '.join(map(repr, Newmark.SCHEMES))}, found {value!r}")
        else:
            low, high = OPTION_RANGES[key]
            value = t.number(key)
            if not low <= value <= high:
                raise t.fail(key, f"expected a number in [{low:.4g}, {high:.4g}], found {value!r}")
        options.append((key, value))
    t.finish(("method", "rtol", "atol", "dt", *METHOD_OPTIONS))
    return SolverSpec(method=method, rtol=rtol, atol=atol, dt=dt, options=tuple(options))


SWEEP_KEYS = ("parameter", "values", "labels", "ic", "frequency", "normalized", "input", "direction",
              "measure", "quantity", "metric", "method")


def _read_sweep(t: _Table) -> tuple[tuple[str, Any], ...]:
    # Types only: the sweep command reads the contents and names this file in its errors.
    items = []
    for key in SWEEP_KEYS:
        if not t.has(key):
            continue
        value = t.raw(key)
        if key in ("normalized", "measure"):
            if not isinstance(value, bool):
                raise t.fail(key, f"expected true or false, found {_kind(value)}")
        elif key in ("parameter", "labels", "ic"):
            if isinstance(value, str) and key == "parameter":
                value = [value]
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise t.fail(key, f"expected a string or an array of strings, found {_kind(value)}")
            value = tuple(value)
        elif key == "values":
            value = _sweep_values(t, value)
        elif key == "frequency":
            if isinstance(value, list):
                value = t.numbers(key)
            elif not isinstance(value, str):
                raise t.fail(key, f"expected an array of numbers or a range string, found {_kind(value)}")
        elif not isinstance(value, str):
            raise t.fail(key, f"expected a string, found {_kind(value)}")
        items.append((key, value))
    t.finish(SWEEP_KEYS)
    return tuple(items)


def _sweep_values(t: _Table, value: Any) -> tuple:
    """One value spec (a range string or an array of numbers), or an array of such specs (one per parameter)."""
    def one(v, where):
        if isinstance(v, str):
            return v
        if isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return tuple(t._check_number(f"{where}[{i}]", x, None, False) for i, x in enumerate(v))
        raise t.fail(where, f"expected an array of numbers or a range string, found {_kind(v)}")

    if isinstance(value, list) and value and all(isinstance(v, (list, str)) for v in value):
        return tuple(one(v, f"values[{i}]") for i, v in enumerate(value))
    return (one(value, "values"),)
