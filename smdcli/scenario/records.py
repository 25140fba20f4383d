"""Two-column text files: table forces and ground-motion records (time, value; CSV or whitespace; header optional);
record files of other formats (AT2, COSMOS, one-column) and read_record are record_files'.

A record is a ground acceleration sampled in time: read, converted to m/s^2 (its file's unit or `units`, then
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


MAX_ROWS = 1_000_000  # rows of a table or record file: 16 min at 1 kHz, 10 s at 100 kHz
_SEPARATORS = str.maketrans({",": " ", ";": " ", "\t": " "})


RECORD_COLUMNS = ("time", "value", "times")  # what a message calls the columns: first, second, the first's plural


def two_columns(text: str, columns: tuple[str, str, str] = RECORD_COLUMNS) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(times, values) of two-column text: separated by commas, semicolons, tabs or spaces; blank lines and lines
    starting with # skipped; a first row that does not start with a number is a header, whatever its separators;
    a byte-order mark is ignored. Checked: finite numbers, strictly increasing times, slopes that stay finite.
    Messages name the columns as `columns` do."""
    import io

    text = text.replace("\ufeff", "")
    lines = text.count("\n") + 1
    if lines > MAX_ROWS + 1000:  # counted before anything is parsed: a size refusal costs a scan, not a parse
        raise ColumnsError(f"has {lines} lines, more than the {MAX_ROWS} rows a table or record may have")
    body = _without_header(text)
    try:
        with np.errstate(all="ignore"):
            table = np.loadtxt(io.StringIO(body.translate(_SEPARATORS)), comments="#", ndmin=2, dtype=float)
    except ValueError:
        table = None
    if table is None or table.shape[1] != 2 or not len(table):
        return _slow_two_columns(text, columns)  # says which line is wrong
    if len(table) > MAX_ROWS:
        raise ColumnsError(f"has {len(table)} rows, more than the {MAX_ROWS} a table or record may have")
    times, values = table[:, 0], table[:, 1]
    bad = ~np.isfinite(table).all(axis=1)
    if bad.any():
        row = int(np.argmax(bad))
        raise ColumnsError(f"line {_line_of_row(text, row)}: expected finite numbers, found "
                           f"{_line_text(text, _line_of_row(text, row))!r}")
    steps = np.diff(times)
    if (steps <= 0).any():
        row = int(np.argmax(steps <= 0)) + 1
        raise ColumnsError(f"line {_line_of_row(text, row)}: expected strictly increasing {columns[2]}, found "
                           f"{times[row]:g} after {times[row - 1]:g}")
    problem = slope_problem(times, values)
    if problem is not None:
        row, message = problem
        raise ColumnsError(f"line {_line_of_row(text, row)}: {message}")
    return tuple(times.tolist()), tuple(values.tolist())


def slope_problem(times, values) -> tuple[int, str] | None:
    """(row, why) where samples cannot be interpolated in double precision: the time span or a step overflows,
    a step is subnormal, or a slope between neighbours overflows; None when every interval is sound."""
    t = np.asarray(times, dtype=float)
    v = np.asarray(values, dtype=float)
    if len(t) < 2:
        return None
    with np.errstate(all="ignore"):
        steps = np.diff(t)
        if not np.isfinite(t[-1] - t[0]):
            return len(t) - 1, f"expected a time span that is a finite number, found {t[-1]:g} - {t[0]:g}"
        tiny = np.finfo(float).tiny
        small = steps < tiny
        if small.any():
            row = int(np.argmax(small)) + 1
            return row, (f"expected a time step of at least {tiny:.3g} s (a normal double), found {steps[row - 1]:.3g} "
                         "s, below what double precision resolves")
        slopes = np.diff(v) / steps
        bad = ~np.isfinite(slopes)
        if bad.any():
            row = int(np.argmax(bad)) + 1
            return row, (f"the slope between this sample and the one before, {v[row] - v[row - 1]:.3g} over "
                         f"{steps[row - 1]:.3g} s, overflows double precision")
    return None


def _without_header(text: str) -> str:
    """The text with a header row's words removed (its line kept, so that numpy's rows map to the file's lines)."""
    start = 0
    while start < len(text):
        end = text.find("\n", start)
        end = len(text) if end < 0 else end
        line = text[start:end].strip()
        if line and not line.startswith("#"):
            return text[:start] + text[end:] if _is_header(line) else text
        start = end + 1
    return text


def _is_header(line: str) -> bool:
    """A first row whose first cell is not a number names the columns."""
    first = _cells(line)[0]
    try:
        float(first)
    except ValueError:
        return True
    return False


def _cells(line: str) -> list[str]:
    return [c for c in re.split(r"\s*[,;\t]\s*|\s+", line.strip()) if c != ""]


def _line_of_row(text: str, row: int) -> int:
    """The 1-based line number of data row `row` (0-based, header, blank and comment lines not counted)."""
    seen = -1
    header_done = False
    for number, line in enumerate(text.split("\n"), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if not header_done:
            header_done = True
            if _is_header(stripped):
                continue
        seen += 1
        if seen == row:
            return number
    return number


def _line_text(text: str, number: int) -> str:
    return text.split("\n")[number - 1].strip()[:40]


def _slow_two_columns(text: str, columns: tuple[str, str, str]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Line by line, to name the first line that is not two finite numbers."""
    times: list[float] = []
    values: list[float] = []
    seen_row = False
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        cells = _cells(stripped)
        if not seen_row and _is_header(stripped):
            seen_row = True
            continue
        seen_row = True
        try:
            numbers = [float(c) for c in cells]
        except ValueError:
            raise ColumnsError(f"line {number}: expected two numbers ({columns[0]}, {columns[1]}), found "
                               f"{stripped[:40]!r}") from None
        if len(numbers) != 2:
            raise ColumnsError(f"line {number}: expected two columns ({columns[0]}, {columns[1]}), found {len(numbers)}")
        if not all(math.isfinite(x) for x in numbers):
            raise ColumnsError(f"line {number}: expected finite numbers, found {stripped[:40]!r}")
        if times and numbers[0] <= times[-1]:
            raise ColumnsError(f"line {number}: expected strictly increasing {columns[2]}, found {numbers[0]:g} "
                               f"after {times[-1]:g}")
        times.append(numbers[0])
        values.append(numbers[1])
    if not times:
        raise ColumnsError("no data rows")
    # numpy refused what Python's float() reads (digit separators such as 1_000): the same checks as the fast path
    problem = slope_problem(times, values)
    if problem is not None:
        raise ColumnsError(f"line {_line_of_row(text, problem[0])}: {problem[1]}")
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


def read_columns(path: Path, columns: tuple[str, str, str]) -> tuple[np.ndarray, np.ndarray]:
    """The two columns of a table file (a PSD profile, a design spectrum), read and checked as a record's are;
    ColumnsError names what is wrong, calling the columns as `columns` do (first, second, the first's plural)."""
    first, second = two_columns(read_text(path), columns)
    return np.asarray(first, dtype=float), np.asarray(second, dtype=float)


@dataclass(frozen=True)
class Record:
    """A ground acceleration record in m/s^2."""

    path: str
    time: np.ndarray
    acceleration: np.ndarray
    units: str  # as the file gave it: "g" or "m/s^2"
    text: str  # the file as read, kept in result files for provenance
    format: str = "csv"  # how it was read (record_files.FORMATS)
    channel: int | None = None  # a COSMOS file's acceleration series read (1-based)

    @property
    def step(self) -> float:
        """The sampling interval, s (records are uniformly sampled)."""
        return float(self.time[1] - self.time[0])

    def drift_warning(self) -> str | None:
        """A line when the velocity or displacement integrated from the record ends far from rest: a baseline left
        uncorrected."""
        from scipy.integrate import cumulative_trapezoid

        velocity = cumulative_trapezoid(self.acceleration, self.time, initial=0.0)
        return velocity_drift(self.path, velocity, cumulative_trapezoid(velocity, self.time, initial=0.0))


def velocity_drift(where: str, velocity: np.ndarray, displacement: np.ndarray | None = None) -> str | None:
    """A warning line where a velocity integrated from a record ends beyond DRIFT_BOUND of its peak, or the
    displacement integrated again does (a velocity may end near zero while the displacement has drifted all the
    way): a baseline left uncorrected; None otherwise."""
    for name, values, units in (("velocity", velocity, "m/s"), ("displacement", displacement, "m")):
        if values is None or not len(values):
            continue
        peak = float(np.abs(values).max(initial=0.0))
        end = float(values[-1])
        if peak > 0 and abs(end) > DRIFT_BOUND * peak:
            return (f"warning: {where}: the {name} integrated from the record ends at {end:.4g} {units}, "
                    f"{abs(end) / peak:.0%} of its peak {peak:.4g} {units} (bound {DRIFT_BOUND:.0%}): "
                    "a baseline correction may be missing")
    return None


def check_scaled(file: str, field: str | None, times, values, units: str) -> None:
    """Samples after scale, shift and unit conversion: finite, with finite slopes between them (ScenarioError)."""
    values = np.asarray(values, dtype=float)
    bad = ~np.isfinite(values)
    key = f"{field}.scale" if field else "scale"
    if bad.any():
        i = int(np.argmax(bad))
        raise ScenarioError(file, key, f"sample {i} at t = {times[i]:g} s overflows double precision once scaled and "
                                       f"converted to {units}; expected finite values")
    problem = slope_problem(times, values)
    if problem is not None:
        i, why = problem
        raise ScenarioError(file, key, f"sample {i} at t = {times[i]:g} s, once scaled and converted to {units}: {why}")


def sampled_record(file: str, field: str | None, path: str, times, acceleration, units: str, text: str) -> Record:
    """A Record of samples in m/s^2, checked: at least 3, uniformly spaced (to the file's rounding of times)."""
    t = np.asarray(times, dtype=float)
    if len(t) < 3:
        raise ScenarioError(file, field, f"expected a record of at least 3 samples, found {len(t)}")
    steps = np.diff(t)
    if steps.max() - steps.min() > 1e-6 * steps.mean():
        raise ScenarioError(file, field, f"expected uniformly sampled times, found steps from {steps.min():.6g} to "
                                         f"{steps.max():.6g} s")
    if not np.array_equal(t, t[0] + (t[1] - t[0]) * np.arange(len(t))):  # a file that gives its dt is exact already
        t = t[0] + steps.mean() * np.arange(len(t))  # the sampling interval the file's rounding of times meant
    return Record(path, t, np.asarray(acceleration, dtype=float), units, text)


# Processing a record (smd record, and [ground_motion] with baseline or filter): what the least-squares polynomial
# subtracted has as its degree, by the name the option and key take.
BASELINES = {"none": -1, "linear": 1, "quadratic": 2}


def baseline_corrected(time: np.ndarray, acceleration: np.ndarray, degree: int) -> np.ndarray:
    """a minus its least-squares polynomial of this degree (none for degree < 0)."""
    if degree < 0:
        return np.asarray(acceleration, dtype=float).copy()
    x = (time - time[0]) / max(time[-1] - time[0], np.finfo(float).tiny)  # on [0, 1]: a well-conditioned fit
    basis = np.vander(x, degree + 1)
    coef, *_ = np.linalg.lstsq(basis, acceleration, rcond=None)
    return acceleration - basis @ coef


def band_passed(acceleration: np.ndarray, step: float, low: float, high: float, order: int) -> np.ndarray:
    """Zero-phase Butterworth: band-pass LOW..HIGH Hz, low-pass where low = 0, high-pass where high = 0."""
    from scipy.signal import butter, sosfiltfilt

    fs = 1.0 / step
    if low > 0 and high > 0:
        sos = butter(order, [low, high], btype="bandpass", fs=fs, output="sos")
    elif high > 0:
        sos = butter(order, high, btype="lowpass", fs=fs, output="sos")
    else:
        sos = butter(order, low, btype="highpass", fs=fs, output="sos")
    return sosfiltfilt(sos, acceleration)
