"""Reading one TOML table: typed fields, unknown keys named with the key they most likely mean, files read
without blocking.

Must not import: model, solvers, or any layer above."""

from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Any

from smdcli.errors import ScenarioError


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


class _Table:
    """Reads the keys of one TOML table, checking each, then refuses leftovers."""

    def __init__(self, file: str, path: str, data: Any, allowed: tuple[str, ...] | None = None):
        if not isinstance(data, dict):
            raise ScenarioError(file, path, f"expected a table, found {_kind(data)}")
        self.file, self.path, self.data = file, path, data
        self.used: set[str] = set()
        self.unit_strings: set[str] = set()  # keys given as "<number> <unit>" strings (already converted to SI)
        self.units: dict[str, str] = {}  # SI units of keys whose meaning the table's context sets (a force's amplitude)
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

    def _given(self, key: str, default: Any, expected: str) -> bool:
        """Whether the key is present; a required one (no default) that is absent is an error."""
        if key in self.data:
            return True
        if default is ...:
            raise self.missing(key, expected)
        return False

    def raw(self, key: str) -> Any:
        """The value as TOML gave it, marked as used."""
        self.used.add(key)
        return self.data[key]

    def number(self, key: str, default: Any = ..., *, unit: str | None = None, minimum: float | None = None,
               positive: bool = False) -> float:
        """A finite real number in SI, or a "<number> <unit>" string converted to `unit` (the field's SI unit; by
        default the one smdcli.scenario.units.FIELD_UNITS gives its key); `minimum` inclusive, `positive` strict."""
        unit = self._unit(key, unit)
        if not self._given(key, default, "a number"):
            return default
        value = self.raw(key)
        return self._check_number(key, value, minimum, positive, unit)

    def _unit(self, key: str, unit: str | None) -> str:
        """The field's SI unit: given, set for this table, or its key's (a missing entry is a reader's bug, raised
        for every value, numbers included)."""
        from smdcli.scenario.units import FIELD_UNITS

        base = key.split("[")[0]
        return unit if unit is not None else self.units[base] if base in self.units else FIELD_UNITS[base]

    def _check_number(self, key, value, minimum, positive, unit: str) -> float:
        if isinstance(value, str):
            from smdcli.scenario.units import UnitError, to_si

            try:
                value = to_si(value, unit)
            except UnitError as exc:
                raise self.fail(key, str(exc)) from None
            self.unit_strings.add(key.split("[")[0])
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

    def boolean(self, key: str, default: bool) -> bool:
        """true or false."""
        if not self.has(key):
            return default
        value = self.raw(key)
        if not isinstance(value, bool):
            raise self.fail(key, f"expected true or false, found {_kind(value)}")
        return value

    def integer(self, key: str, default: Any = ..., *, minimum: int = 0) -> int:
        """A whole number >= minimum."""
        if not self._given(key, default, "a whole number"):
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
               suggest: bool = True) -> str:
        """A string, optionally one of `choices` (control characters were refused for the whole document); a near
        spelling suggested unless `suggest` is off (units: a near spelling is another magnitude)."""
        if not self._given(key, default, "a string"):
            return default
        value = self.raw(key)
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, found {_kind(value)}")
        if choices is not None and value not in choices:
            hint = difflib.get_close_matches(value, choices, n=1) if suggest else None
            extra = f" (did you mean {hint[0]!r}?)" if hint else ""
            raise self.fail(key, f"expected one of {', '.join(choices)}, found {value!r}{extra}")
        return value

    def numbers(self, key: str, default: Any = ..., *, unit: str | None = None, length: int | None = None,
                minimum: float | None = None) -> tuple[float, ...]:
        """An array of finite numbers (each a number in SI or a unit string, as `number` reads), optionally of a given
        length."""
        unit = self._unit(key, unit)
        if not self._given(key, default, "an array of numbers"):
            return default
        value = self.raw(key)
        if not isinstance(value, list):
            raise self.fail(key, f"expected an array of numbers, found {_kind(value)}")
        if length is not None and len(value) != length:
            raise self.fail(key, f"expected {length} numbers, found {len(value)}")
        return tuple(self._check_number(f"{key}[{i}]", v, minimum, False, unit) for i, v in enumerate(value))

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


_TOP_KEYS = ("title", "description", "time", "mass", "spring", "damper", "friction", "stop", "system",
             "force", "solver", "sweep", "damping", "ground_motion", "expect", "fit", "optimize", "building", "ida")
_TIME_KEYS = ("start", "end", "step", "points")
_MASS_KEYS = ("name", "m", "x0", "v0")
_SYSTEM_KEYS = ("dofs", "M", "C", "K", "x0", "v0")


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
