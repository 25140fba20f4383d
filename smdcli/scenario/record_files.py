"""Record files in the formats engineers download: PEER NGA `.AT2`, COSMOS v1.20 volume 2 (`.V2`, `.V2c`),
two-column time,value text (`csv`: comma, whitespace or tab separated) and one-column value text with a given
sampling interval, each with or without header lines.

read_samples gives the samples as the file holds them (its numbers, its time axis) with the format and the unit the
file names; read_record converts a record to SI (as a [ground_motion] table does). A malformed file is a
ColumnsError naming the line and what was expected.

Must not import: model, solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.scenario.records import (MAX_ROWS, UNITS, ColumnsError, Record, _cells, _is_header, check_scaled, read_text,
                                     sampled_record, slope_problem, two_columns)

FORMATS = ("at2", "cosmos", "csv", "one_column")
EXTENSIONS = {".at2": "at2", ".v2": "cosmos", ".v2c": "cosmos"}
# the unit names an AT2 file's third line gives, as GROUND_UNITS["acceleration"] calls them (GAL: cm/s^2)
AT2_UNITS = {"G": "g", "GAL": "cm/s^2", "CM/S^2": "cm/s^2", "CM/SEC/SEC": "cm/s^2", "CM/S/S": "cm/s^2",
             "CM/SEC^2": "cm/s^2", "M/S^2": "m/s^2", "M/SEC/SEC": "m/s^2", "M/S/S": "m/s^2"}
# COSMOS Table 2 physical-parameter codes of an acceleration, as GROUND_UNITS["acceleration"] calls them
COSMOS_UNITS = {2: "g", 4: "cm/s^2", 7: "in/s^2", 10: "cm/s^2"}
COSMOS_MILLI_G = 11  # mg: a thousandth of g, read as g times 1e-3
COSMOS_DT = 61  # the real header's sampling interval, ms (its 62nd value)
COSMOS_QUANTITY = 1  # the integer header's kind of series: 1 an acceleration (its 2nd value)
COSMOS_PHYSICAL = 2  # the integer header's physical-parameter code (its 3rd value)


@dataclass(frozen=True)
class Samples:
    """A record file's samples as written: times (s), values in the file's unit, what the file is and says."""

    times: np.ndarray
    values: np.ndarray
    format: str  # one of FORMATS
    units: str | None  # the unit the file names (a GROUND_UNITS["acceleration"] name), None where it names none
    factor: float = 1.0  # what the values are multiplied by to be in `units` (a COSMOS file in mg: 1e-3 g)
    channel: int | None = None  # a COSMOS file's series read (1-based), None for the other formats


def read_record(path: str | Path, units: str | None = None, scale: float = 1.0, shift: float = 0.0,
                field: str | None = None, format: str | None = None, channel: int | None = None,
                dt: float | None = None) -> Record:
    """The record in a file, in m/s^2: (value * scale + shift) * units. Two-column text by default, or a PEER AT2,
    COSMOS V2 or one-column file as `format`, its extension or `dt` say (record_files); units the file's own where it
    names them (AT2, COSMOS: a different `units` is refused), else `units` or g. Input errors name the file and,
    within a scenario, the field."""
    path = Path(path)
    where = str(path) if field is None else field
    if units is not None and units not in UNITS:
        raise ScenarioError(str(path), f"{field}.units" if field else "units",
                            f"expected one of {', '.join(repr(u) for u in UNITS)}, found {units!r}")
    for name, value in (("scale", scale), ("shift", shift)):
        if not math.isfinite(value):
            raise ScenarioError(str(path), f"{field}.{name}" if field else name, f"expected a finite number, found {value}")
    try:
        text = read_text(path)
        samples = read_samples(path, text, format, channel, dt)
    except ColumnsError as exc:
        raise ScenarioError(where, None if field is None else "file", f"{path}: {exc}" if field else str(exc)) from None
    if samples.units is not None:
        if units is not None and UNITS[units] != UNITS[samples.units]:
            raise ScenarioError(str(path), f"{field}.units" if field else "units",
                                f"the file gives its values in {samples.units}; {units!r} disagrees (leave the units "
                                "out: the file's are used)")
        units = samples.units
    units = units or "g"
    with np.errstate(all="ignore"):
        acceleration = (samples.values * samples.factor * scale + shift) * UNITS[units]
    check_scaled(str(path), field, samples.times, acceleration, "m/s^2")
    return replace(sampled_record(where, None, str(path), samples.times, acceleration, units, text),
                   format=samples.format, channel=samples.channel)


def format_of(path: Path, given: str | None, dt: float | None) -> str:
    """The format a record file is read as: `given`, else by its extension (.AT2, .V2, .V2c), else one-column text
    where a sampling interval is given and two-column text otherwise."""
    if given is not None:
        if given not in FORMATS:
            raise ColumnsError(f"format: expected one of {', '.join(FORMATS)}, found {given!r}")
        return given
    return EXTENSIONS.get(path.suffix.lower(), "one_column" if dt is not None else "csv")


def read_samples(path: Path, text: str | None = None, format: str | None = None, channel: int | None = None,
                 dt: float | None = None) -> Samples:
    """The samples of a record file (text: its contents where already read). dt is a one-column file's sampling
    interval and nothing else's; channel the 1-based position of a COSMOS file's acceleration series."""
    kind = format_of(path, format, dt)
    if dt is not None and kind != "one_column":
        raise ColumnsError(f"dt: only a one-column file takes a sampling interval; a {kind} file gives its own")
    if channel is not None and kind != "cosmos":
        raise ColumnsError(f"channel: only a COSMOS file has channels; this is read as {kind}")
    if kind == "one_column" and dt is None:
        raise ColumnsError("a one-column file needs its sampling interval: dt = SECONDS (smd record --dt)")
    return _parsed(kind, read_text(path) if text is None else text, channel, dt)


@lru_cache(maxsize=8)
def _parsed(kind: str, text: str, channel: int | None, dt: float | None) -> Samples:
    """A record's samples from its text, parsed once per text (a fit or a sensitivity builds its scene again at
    every trial point: 7 ms a build for the Bouc-Wen benchmark's table); its arrays read-only, being shared."""
    if kind == "at2":
        found = _at2(text)
    elif kind == "cosmos":
        found = _cosmos(text, 1 if channel is None else channel)
    elif kind == "one_column":
        found = _one_column(text, dt)
    else:
        times, values = two_columns(text)
        found = Samples(np.asarray(times), np.asarray(values), "csv", None)
    for array in (found.times, found.values):
        array.setflags(write=False)
    return found


def _lines(text: str) -> list[str]:
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def _numbers(lines: list[str], first: int, count: int, what: str, width: int | None = None) -> tuple[np.ndarray, int]:
    """count numbers from lines[first:] (line numbers 1-based in messages), whitespace separated or, with width,
    in fixed-width fields, and the line after the last one read (0-based); ColumnsError naming the line that is
    short, not a number, or has numbers left over."""
    out: list[float] = []
    number = last = first
    while len(out) < count:
        if number >= len(lines) or not lines[number].strip() and number == len(lines) - 1:
            raise ColumnsError(f"line {last}: expected {count} {what}, the file ends after {len(out)}")
        line = lines[number].rstrip()
        cells = [line[i:i + width] for i in range(0, len(line), width)] if width else line.split()
        for cell in cells:
            if not cell.strip():
                continue
            try:
                value = float(cell.replace("D", "E").replace("d", "e"))
            except ValueError:
                raise ColumnsError(f"line {number + 1}: expected {what} (numbers), found {cell.strip()[:20]!r}") \
                    from None
            if not math.isfinite(value):
                raise ColumnsError(f"line {number + 1}: expected finite {what}, found {cell.strip()!r}")
            out.append(value)
        if len(out) > count:
            raise ColumnsError(f"line {number + 1}: expected {count} {what} in all, found {len(out)} by this line")
        if line.strip():
            last = number + 1
        number += 1
    return np.array(out, dtype=float), number


def _at2(text: str) -> Samples:
    """PEER NGA: four header lines (the third names the unit, the fourth NPTS and DT in either layout), then NPTS
    values, five a line."""
    lines = _lines(text)
    if len(lines) < 4:
        raise ColumnsError(f"line {len(lines)}: expected an AT2 file's four header lines, the file ends")
    found = re.search(r"UNITS\s+OF\s+(\S+)", lines[2], re.IGNORECASE)
    name = found.group(1).upper().rstrip(".,") if found else lines[2].strip()[:30]
    if name not in AT2_UNITS:
        raise ColumnsError(f"line 3: expected the unit of the acceleration (UNITS OF G, GAL, CM/S^2, CM/SEC/SEC or "
                           f"M/S^2), found {name!r}")
    npts, dt = _at2_sampling(lines[3])
    if len(lines) - 4 > MAX_ROWS:
        raise ColumnsError(f"has {len(lines)} lines, more than the {MAX_ROWS} rows a record may have")
    values, after = _numbers(lines, 4, npts, "acceleration values")
    rest = next((i for i in range(after, len(lines)) if lines[i].strip()), None)
    if rest is not None:
        raise ColumnsError(f"line {rest + 1}: expected the file to end after its NPTS = {npts} values, found "
                           f"{lines[rest].strip()[:30]!r}")
    return Samples(dt * np.arange(npts), values, "at2", AT2_UNITS[name])


def _at2_sampling(line: str) -> tuple[int, float]:
    """NPTS and DT of an AT2 file's fourth line: `NPTS= 4001, DT= .0050 SEC` or `4001 0.0050 NPTS, DT`."""
    labelled = re.search(r"NPTS\s*=\s*([^,\s]+)\s*,?\s*DT\s*=\s*([^\s,]+)", line, re.IGNORECASE)
    bare = re.match(r"\s*(\S+)\s+(\S+)\s+NPTS\s*,\s*DT", line, re.IGNORECASE)
    found = labelled or bare
    if not found:
        raise ColumnsError(f"line 4: expected NPTS and DT (NPTS= 4001, DT= .0050 SEC, or 4001 0.0050 NPTS, DT), "
                           f"found {line.strip()[:50]!r}")
    try:
        npts, dt = int(found.group(1)), float(found.group(2))
    except ValueError:
        raise ColumnsError(f"line 4: expected a whole NPTS and a number DT, found {found.group(1)!r} and "
                           f"{found.group(2)!r}") from None
    if npts < 1 or npts > MAX_ROWS:
        raise ColumnsError(f"line 4: expected NPTS from 1 to {MAX_ROWS}, found {npts}")
    if not (math.isfinite(dt) and dt > 0):
        raise ColumnsError(f"line 4: expected a positive DT in seconds, found {found.group(2)}")
    return npts, dt


_COSMOS_BLOCK = re.compile(r"^\s*(\d+)\s+(Integer|Real)-header values follow on\s+(\d+)\s+lines", re.IGNORECASE)
_COSMOS_COMMENTS = re.compile(r"^\s*(\d+)\s+Comment line", re.IGNORECASE)
_COSMOS_DATA = re.compile(r"^\s*(\d+)\s+(\w+)\s+pts", re.IGNORECASE)
_FORMAT = re.compile(r"Format\s*=\s*\(\s*(\d+)\s*[A-Z]\s*(\d+)", re.IGNORECASE)


def _cosmos(text: str, channel: int) -> Samples:
    """COSMOS v1.20 volume 2: per series a text header, an integer header and a real header (their counts, lines and
    Fortran formats stated), comment lines, then `N <quantity> pts, ... Format=(8F10.5)` and the values; the
    channel-th acceleration series (1-based) is read, its sampling interval from the real header (ms), its unit
    from the integer header's physical-parameter code."""
    lines = _lines(text)
    if channel < 1:
        raise ColumnsError(f"channel: expected a position from 1, found {channel}")
    seen, number = 0, 0
    while True:
        integers, reals, number = _cosmos_headers(lines, number)
        count, quantity, data_line = _cosmos_data_line(lines, number)
        width = _width(lines[number], number)
        is_acceleration = quantity.lower().startswith("accel") and int(integers[COSMOS_QUANTITY]) in (1, -999)
        if is_acceleration:
            seen += 1
        if is_acceleration and seen == channel:
            break
        number = _next_series(lines, data_line + math.ceil(count / max(1, _per_line(lines[number]))))
        if number is None:
            raise ColumnsError(f"channel: expected at least {channel} acceleration series, found {seen}")
    if len(reals) <= COSMOS_DT or not reals[COSMOS_DT] > 0:
        raise ColumnsError(f"line {data_line}: expected the real header's 62nd value, the sampling interval in ms, "
                           "to be positive")
    code = int(integers[COSMOS_PHYSICAL]) if len(integers) > COSMOS_PHYSICAL else -999
    if code not in COSMOS_UNITS and code != COSMOS_MILLI_G:
        raise ColumnsError(f"line {data_line}: expected an acceleration's unit code (2 g, 4 cm/s/s, 7 in/s/s, 10 gal, "
                           f"11 mg) as the integer header's 3rd value, found {code}")
    values = _numbers(lines, data_line, count, "acceleration values", width)[0]
    dt = float(reals[COSMOS_DT]) / 1000.0
    milli = code == COSMOS_MILLI_G
    return Samples(dt * np.arange(count), values, "cosmos", "g" if milli else COSMOS_UNITS[code],
                   1e-3 if milli else 1.0, channel)


def _cosmos_headers(lines: list[str], start: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The integer and real headers of the series whose text header starts at or after `start`, and the line after
    its comments (0-based)."""
    number = start
    headers = {}
    while len(headers) < 2:
        while number < len(lines) and not _COSMOS_BLOCK.match(lines[number]):
            number += 1
        if number >= len(lines):
            raise ColumnsError(f"line {number}: expected a COSMOS '<N> Integer-header values follow on <L> lines' "
                               "and 'Real-header' line, the file ends")
        found = _COSMOS_BLOCK.match(lines[number])
        count, kind, rows = int(found.group(1)), found.group(2).lower(), int(found.group(3))
        width = _width(lines[number], number)
        headers[kind] = _numbers(lines[:number + 1 + rows], number + 1, count, f"{kind}-header values", width)[0]
        number += 1 + rows
    found = _COSMOS_COMMENTS.match(lines[number]) if number < len(lines) else None
    if found is None:
        raise ColumnsError(f"line {number + 1}: expected '<N> Comment line(s) follow' after the real header")
    return headers["integer"], headers["real"], number + 1 + int(found.group(1))


def _cosmos_data_line(lines: list[str], number: int) -> tuple[int, str, int]:
    """(count, quantity, first data line 0-based) of the data block's header line at `number`."""
    found = _COSMOS_DATA.match(lines[number]) if number < len(lines) else None
    if found is None:
        raise ColumnsError(f"line {number + 1}: expected '<N> acceleration pts, ... Format=(...)' before the values, "
                           f"found {lines[number].strip()[:40] if number < len(lines) else 'the end'!r}")
    count = int(found.group(1))
    if count < 1 or count > MAX_ROWS:
        raise ColumnsError(f"line {number + 1}: expected from 1 to {MAX_ROWS} points, found {count}")
    return count, found.group(2), number + 1


def _width(line: str, number: int) -> int:
    found = _FORMAT.search(line)
    if found is None:
        raise ColumnsError(f"line {number + 1}: expected a Fortran format (Format=(8F10.5)), found "
                           f"{line.strip()[:60]!r}")
    return int(found.group(2))


def _per_line(line: str) -> int:
    return int(_FORMAT.search(line).group(1))


def _next_series(lines: list[str], number: int) -> int | None:
    """The line after a series' end-of-data line (0-based), or None at the file's end."""
    while number < len(lines) and not lines[number].strip():
        number += 1
    if number < len(lines) and lines[number].lower().lstrip().startswith("end-of-data"):
        number += 1
    return number if any(line.strip() for line in lines[number:]) else None


def _one_column(text: str, dt: float) -> Samples:
    """One value a line at sampling interval dt: header lines (whatever does not start with a number) and lines
    starting with # skipped."""
    if not (math.isfinite(dt) and dt > 0):
        raise ColumnsError(f"dt: expected a positive sampling interval in seconds, found {dt:g}")
    values: list[float] = []
    for number, line in enumerate(_lines(text), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#") or (not values and _is_header(stripped)):
            continue
        cells = _cells(stripped)
        if len(cells) != 1:
            raise ColumnsError(f"line {number}: expected one value a line, found {len(cells)} (two-column text: "
                               "no dt)")
        try:
            value = float(cells[0])
        except ValueError:
            raise ColumnsError(f"line {number}: expected a number, found {stripped[:30]!r}") from None
        if not math.isfinite(value):
            raise ColumnsError(f"line {number}: expected a finite number, found {stripped[:30]!r}")
        values.append(value)
        if len(values) > MAX_ROWS:
            raise ColumnsError(f"has more than the {MAX_ROWS} rows a record may have")
    if not values:
        raise ColumnsError("no data rows")
    times = dt * np.arange(len(values))
    problem = slope_problem(times, values)
    if problem is not None:
        raise ColumnsError(problem[1])
    return Samples(times, np.array(values), "one_column", None)
