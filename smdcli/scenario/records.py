"""Two-column text files: table forces and ground-motion records (time, value; CSV or whitespace; header optional).

A record is a ground acceleration sampled in time: read, converted to m/s^2 (`units` "g" or "m/s^2", then
`scale` and `shift`), and checked: strictly increasing times, finite numbers, two columns on every row.

Must not import: model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.scenario.reader import MAX_TABLE_BYTES, _NotRegular, read_regular_file
from smdcli.scenario.spec import GROUND_UNITS

UNITS = GROUND_UNITS["acceleration"]
DRIFT_BOUND = 0.05  # a record's integrated velocity ending beyond this fraction of its peak gets a warning


class ColumnsError(ValueError):
    """A row that is not two finite numbers, or times that do not increase; the message names the line."""


def two_columns(text: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(times, values) of two-column text: separated by commas, semicolons, tabs or spaces; blank lines and lines
    starting with # skipped; a first row that is not numbers is a header."""
    times: list[float] = []
    values: list[float] = []
    seen_row = False
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        cells = [c for c in re.split(r"\s*[,;\t]\s*|\s+", stripped) if c != ""]
        try:
            numbers = [float(c) for c in cells]
        except ValueError:
            if not seen_row and len(cells) == 2:
                seen_row = True
                continue  # a header row
            raise ColumnsError(f"line {number}: expected two numbers (time, value), found {stripped[:40]!r}") from None
        seen_row = True
        if len(numbers) != 2:
            raise ColumnsError(f"line {number}: expected two columns (time, value), found {len(numbers)}")
        if not all(math.isfinite(x) for x in numbers):
            raise ColumnsError(f"line {number}: expected finite numbers, found {stripped[:40]!r}")
        if times and numbers[0] <= times[-1]:
            raise ColumnsError(f"line {number}: expected strictly increasing times, found {numbers[0]:g} after "
                               f"{times[-1]:g}")
        times.append(numbers[0])
        values.append(numbers[1])
    if not times:
        raise ColumnsError("no data rows")
    return tuple(times), tuple(values)


def read_text(path: Path) -> str:
    """A table or record file's text; OSError and decoding failures become one line naming why."""
    try:
        return read_regular_file(path, MAX_TABLE_BYTES).decode("utf-8")
    except _NotRegular as exc:
        raise ColumnsError(f"{exc}, expected a text file of two columns") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ColumnsError("no such file" if isinstance(exc, FileNotFoundError) else
                           "is a directory" if isinstance(exc, IsADirectoryError) else
                           "cannot be read as UTF-8 text") from None


@dataclass(frozen=True)
class Record:
    """A ground acceleration record in m/s^2."""

    path: str
    time: np.ndarray
    acceleration: np.ndarray
    units: str  # as the file gave it: "g" or "m/s^2"
    text: str  # the file as read, kept in result files for provenance

    @property
    def step(self) -> float:
        """The sampling interval, s (records are uniformly sampled)."""
        return float(self.time[1] - self.time[0])

    def drift_warning(self) -> str | None:
        """A line when the velocity integrated from the record ends far from rest: a baseline left uncorrected."""
        from scipy.integrate import cumulative_trapezoid

        return velocity_drift(self.path, cumulative_trapezoid(self.acceleration, self.time, initial=0.0))


def velocity_drift(where: str, velocity: np.ndarray) -> str | None:
    """A warning line where a velocity integrated from a record ends beyond DRIFT_BOUND of its peak: a baseline
    left uncorrected; None otherwise."""
    peak = float(np.abs(velocity).max(initial=0.0))
    end = float(velocity[-1])
    if peak > 0 and abs(end) > DRIFT_BOUND * peak:
        return (f"warning: {where}: the velocity integrated from the record ends at {end:.4g} m/s, "
                f"{abs(end) / peak:.0%} of its peak {peak:.4g} m/s (bound {DRIFT_BOUND:.0%}): "
                "a baseline correction may be missing")
    return None


def read_record(path: str | Path, units: str = "g", scale: float = 1.0, shift: float = 0.0,
                field: str | None = None) -> Record:
    """The record in a two-column file, in m/s^2: (value * scale + shift) * units. Input errors name the file and,
    within a scenario, the field."""
    path = Path(path)
    where = str(path) if field is None else field
    if units not in UNITS:
        raise ScenarioError(str(path), f"{field}.units" if field else "units",
                            f"expected one of {', '.join(repr(u) for u in UNITS)}, found {units!r}")
    for name, value in (("scale", scale), ("shift", shift)):
        if not math.isfinite(value):
            raise ScenarioError(str(path), f"{field}.{name}" if field else name, f"expected a finite number, found {value}")
    try:
        text = read_text(path)
        times, values = two_columns(text)
    except ColumnsError as exc:
        raise ScenarioError(where, None if field is None else "file", f"{path}: {exc}" if field else str(exc)) from None
    acceleration = (np.asarray(values) * scale + shift) * UNITS[units]
    return sampled_record(where, None, str(path), times, acceleration, units, text)


def sampled_record(file: str, field: str | None, path: str, times, acceleration, units: str, text: str) -> Record:
    """A Record of samples in m/s^2, checked: at least 3, uniformly spaced (to the file's rounding of times)."""
    t = np.asarray(times, dtype=float)
    if len(t) < 3:
        raise ScenarioError(file, field, f"expected a record of at least 3 samples, found {len(t)}")
    steps = np.diff(t)
    if steps.max() - steps.min() > 1e-6 * steps.mean():
        raise ScenarioError(file, field, f"expected uniformly sampled times, found steps from {steps.min():.6g} to "
                                         f"{steps.max():.6g} s")
    t = t[0] + steps.mean() * np.arange(len(t))  # the sampling interval the file's rounding of times meant
    return Record(path, t, np.asarray(acceleration, dtype=float), units, text)
