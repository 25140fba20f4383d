"""Measured response for `smd fit`: a CSV whose first column is time and whose others are named
`<mass>.<displacement|velocity|acceleration>` or `<element>.force` (units optional, `m1.acceleration [g]`), or an
smd HDF5 result. Everything is converted to SI on reading; every malformed cell is refused naming the file, the
row and the column. A Test pairs such data with the scenario they were measured on.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from smdcli.analysis.sensitivity import QUANTITIES as RESPONSE_UNITS
from smdcli.errors import UsageError
from smdcli.scenario import Scenario
from smdcli.scenario.spec import STANDARD_GRAVITY

QUANTITIES = ("displacement", "velocity", "acceleration", "force")
SI_UNITS = {**RESPONSE_UNITS, "force": "N", "time": "s"}
UNITS = {
    "time": {"s": 1.0, "ms": 1e-3},
    "displacement": {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "in": 0.0254, "ft": 0.3048},
    "velocity": {"m/s": 1.0, "mm/s": 1e-3, "cm/s": 1e-2, "in/s": 0.0254, "ft/s": 0.3048},
    "acceleration": {"m/s^2": 1.0, "m/s2": 1.0, "mm/s^2": 1e-3, "cm/s^2": 1e-2, "gal": 1e-2, "g": STANDARD_GRAVITY,
                     "in/s^2": 0.0254, "ft/s^2": 0.3048},
    "force": {"N": 1.0, "kN": 1e3, "mN": 1e-3, "lbf": 4.4482216152605},
}
# a channel and its unit in brackets at the end; the name may hold an element's index (spring[0].force [kN])
_HEADER = re.compile(r"\s*(.+?)\s*(?:\[\s*([^\[\]]*?)\s*\])?\s*")


@dataclass
class Measured:
    """One test's data in SI: times (increasing) and each channel's values at them."""

    file: str
    time: np.ndarray
    channels: dict[str, np.ndarray]  # "m1.acceleration" -> (N,)
    units: dict[str, str]  # the units the file gave each channel in


@dataclass
class Test:
    """One scenario, the data measured on it, the channels fitted and their weights."""

    scenario: Scenario
    measured: Measured
    channels: tuple[str, ...]
    weights: np.ndarray
    grid: np.ndarray  # the scenario's start, then the data's times
    rows: np.ndarray  # where the data's times are in the grid


def quantity_of(channel: str) -> str:
    """The quantity a channel name ends in (displacement, velocity, acceleration or force)."""
    return channel.rsplit(".", 1)[-1]


def read_measured(path: str | Path) -> Measured:
    """A test's data from a CSV (header required) or an smd HDF5 result."""
    path = Path(path)
    if not path.is_file():
        raise UsageError(f"{path}: no such data file")
    if path.suffix.lower() in (".h5", ".hdf5"):
        return _read_hdf5(path)
    return _read_csv(path)


def _read_csv(path: Path) -> Measured:
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"{path}: cannot read the data file ({exc})") from None
    rows = [(i + 1, line) for i, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise UsageError(f"{path}: the data file is empty")
    split = (lambda text: [c.strip() for c in text.split(",")]) if "," in rows[0][1] else str.split
    names, factors, units = [], [], {}
    for column, cell in enumerate(split(rows[0][1]), start=1):
        match = _HEADER.fullmatch(cell)
        name, unit = (match.group(1), match.group(2)) if match else (cell, None)
        if column == 1:
            if name != "time":
                raise UsageError(f"{path}: row {rows[0][0]}, column 1: expected the header 'time' (s), found {cell!r}")
            quantity = "time"
        else:
            quantity = quantity_of(name)
            if "." not in name or quantity not in QUANTITIES:
                raise UsageError(f"{path}: row {rows[0][0]}, column {column}: expected a channel named "
                                 f"<mass>.displacement|velocity|acceleration or <element>.force, found {cell!r}")
            if name in names:
                raise UsageError(f"{path}: row {rows[0][0]}, column {column}: channel {name!r} given twice")
        known = UNITS[quantity]
        if unit is not None and unit not in known:
            raise UsageError(f"{path}: row {rows[0][0]}, column {column}: {unit!r} is not a unit of {quantity} "
                             f"(expected one of {', '.join(known)})")
        names.append(name)
        factors.append(known[unit] if unit is not None else 1.0)
        units[name] = unit or SI_UNITS[quantity]
    values = np.empty((len(rows) - 1, len(names)))
    for r, (number, line) in enumerate(rows[1:]):
        cells = split(line)
        if len(cells) != len(names):
            raise UsageError(f"{path}: row {number}: expected {len(names)} columns, found {len(cells)}")
        for c, cell in enumerate(cells):
            try:
                value = float(cell)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise UsageError(f"{path}: row {number}, column {c + 1} ({names[c]}): expected a finite number, "
                                 f"found {cell!r}")
            values[r, c] = value * factors[c]
    if len(values) < 2:
        raise UsageError(f"{path}: expected at least two rows of data, found {len(values)}")
    time = values[:, 0]
    steps = np.diff(time)
    if np.any(steps <= 0):
        bad = int(np.flatnonzero(steps <= 0)[0])
        raise UsageError(f"{path}: row {rows[bad + 2][0]}, column 1 (time): times must increase; {time[bad + 1]:g} "
                         f"follows {time[bad]:g}")
    channels = {name: values[:, c] for c, name in enumerate(names) if c > 0}
    return Measured(str(path), time, channels, {k: v for k, v in units.items() if k != "time"})


def _read_hdf5(path: Path) -> Measured:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            time = f["time"][()]
            dofs = [d.decode() if isinstance(d, bytes) else str(d) for d in f["dof"][()]]
            channels = {}
            for quantity in ("displacement", "velocity", "acceleration"):
                # an accelerometer reads the absolute acceleration under support motion
                source = "absolute_acceleration" if quantity == "acceleration" and "absolute_acceleration" in f \
                    else quantity
                data = f[source][()]
                for j, dof in enumerate(dofs):
                    channels[f"{dof}.{quantity}"] = data[:, j]
    except (OSError, KeyError) as exc:
        raise UsageError(f"{path}: not an smd result with /time, /dof and /displacement ({exc})") from None
    return Measured(str(path), time, channels, {k: SI_UNITS[quantity_of(k)] for k in channels})
