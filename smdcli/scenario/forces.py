"""[[force]] tables and [ground_motion]: a shape's fields read by its class (smdcli.shapes), table forces read
from files.

Must not import: model, solvers, or any layer above."""

from __future__ import annotations

import difflib
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from smdcli.scenario.reader import _Table
from smdcli.scenario.records import (BASELINES, ColumnsError, band_passed, baseline_corrected, check_scaled, read_text,
                                     slope_problem)
from smdcli.scenario.spec import FORCE_TYPES, GROUND, GROUND_QUANTITIES, GROUND_UNITS, ForceSpec, GroundMotionSpec
from smdcli.shapes.registry import SHAPES

_ANY_FORCE_KEYS = ("on", "type") + tuple(dict.fromkeys(k for shape in SHAPES.values() for k in shape.fields))


def _read_force(t: _Table, index: int, dofs: tuple[str, ...]) -> ForceSpec:
    on = t.string("on")
    if on not in dofs:
        hint = difflib.get_close_matches(on, dofs, n=1)
        extra = f" (did you mean {hint[0]!r}?)" if hint else f"; DOFs are {', '.join(dofs)}"
        raise t.fail("on", f"unknown DOF {on!r}{extra}")
    t.units.update(amplitude="N", values="N")
    return _read_shape(t, index, on, ("on",))


def _read_shape(t: _Table, index: int, on: str, others: tuple[str, ...]) -> ForceSpec:
    """A force shape: `type` and the keys its shape reads; `others` are the table's keys read elsewhere."""
    kind = t.string("type", choices=FORCE_TYPES)
    shape = SHAPES[kind]
    spec: dict[str, Any] = {"index": index, "on": on, "type": kind}
    spec.update(_read_table_force(t) if kind == "table" else shape.read(t))  # a table's file is the scenario's
    allowed = others + ("type",) + shape.fields
    for key in t.data:
        owners = [f'"{name}"' for name, other in SHAPES.items() if key in other.fields]
        if key not in allowed and owners:
            raise t.fail(key, f'type = "{kind}" takes no {key} (a field of type = {" or ".join(owners)})')
    t.finish(allowed)
    return ForceSpec(**spec)


PROCESSING_KEYS = ("baseline", "filter", "filter_order")  # a recorded acceleration's processing (smd record's)
GROUND_KEYS = ("quantity", "units", "scale", "shift", "hold") + PROCESSING_KEYS + tuple(k for k in _ANY_FORCE_KEYS
                                                                                    if k != "on")


def _read_ground_motion(t: _Table) -> GroundMotionSpec:
    """[ground_motion]: quantity, a force shape, and for a table its units, scale and shift (converted to SI)."""
    if not t.has("quantity"):
        raise t.missing("quantity", "displacement, velocity or acceleration")
    quantity = t.string("quantity", choices=GROUND_QUANTITIES)
    allowed = GROUND_UNITS[quantity]
    units = t.string("units", next(u for u in allowed if u != "g"), choices=tuple(allowed), suggest=False)
    si_units = next(u for u, f in allowed.items() if f == 1.0)
    t.units.update(amplitude=si_units, values=si_units, shift=si_units)
    table = t.data.get("type") == "table"
    if t.has("hold") and not (table and quantity == "acceleration"):
        raise t.fail("hold", 'only a recorded ground acceleration (quantity = "acceleration", type = "table") ends '
                             "at its last sample; hold keeps its last value instead")
    hold = t.boolean("hold", False)
    for key in ("scale", "shift"):
        if t.has(key) and not table:
            raise t.fail(key, 'only a table ground motion has scale and shift (type = "table"); '
                              "set the amplitude instead")
    scale, shift = t.number("scale", 1.0), t.number("shift", 0.0)
    for key in PROCESSING_KEYS:
        if t.has(key) and not (table and quantity == "acceleration"):
            raise t.fail(key, 'only a recorded ground acceleration is processed (quantity = "acceleration", '
                              'type = "table")')
    baseline = t.string("baseline", "none", choices=tuple(BASELINES))
    band = t.numbers("filter", length=2) if t.has("filter") else None
    order = t.integer("filter_order", 4, minimum=1)
    if t.has("filter_order") and band is None:
        raise t.fail("filter_order", "expected it with filter = [LOW, HIGH]")
    if order > 10:
        raise t.fail("filter_order", f"expected a Butterworth order from 1 to 10, found {order}")
    shape = _read_shape(t, 0, GROUND, ("quantity", "units", "scale", "shift", "hold") + PROCESSING_KEYS)
    if shape.file_units is not None:  # an AT2 or COSMOS record names its own unit
        if quantity != "acceleration":
            raise t.fail("quantity", f"{shape.file}: an {shape.file_format.upper()} file holds an acceleration; "
                                     f"expected quantity = \"acceleration\", found {quantity!r}")
        if t.has("units") and allowed[units] != allowed[shape.file_units]:
            raise t.fail("units", f"{shape.file} gives its values in {shape.file_units}; units = {units!r} disagrees "
                                  "(leave units out: the file's are used)")
        units = shape.file_units
    with_units = sorted(t.unit_strings & {"amplitude", "values"})
    if with_units and t.has("units"):
        raise t.fail("units", f"{with_units[0]} carries its own unit; leave units out, or give {with_units[0]} as "
                              f"plain numbers in {units}")
    factor = 1.0 if with_units else allowed[units]
    if "shift" in t.unit_strings:  # a shift with its unit is in SI; the record's values are in the file's unit
        shift /= factor
    if shape.type == "table":
        shape = replace(shape, values=tuple((v * scale + shift) * factor for v in shape.values))
        if baseline != "none" or band is not None:
            shape = _processed(t, shape, baseline, band, order)
    elif shape.type == "expression":
        if factor != 1.0:
            shape = replace(shape, expr=f"({shape.expr}) * {factor!r}")
    else:
        shape = replace(shape, amplitude=shape.amplitude * factor)
    if shape.type == "table":
        check_scaled(t.file, t.path, shape.t, shape.values, si_units)
    elif not math.isfinite(shape.amplitude):
        raise t.fail("amplitude", f"the amplitude in {si_units} overflows double precision once converted; "
                                  "expected a finite value")
    return GroundMotionSpec(quantity=quantity, shape=shape, units=units, hold=hold)


def _processed(t: _Table, shape: ForceSpec, baseline: str, band, order: int) -> ForceSpec:
    """A recorded acceleration baseline-corrected and band-passed as `smd record` does (uniform samples needed)."""
    times = np.asarray(shape.t, dtype=float)
    values = np.asarray(shape.values, dtype=float)
    if shape.interpolation != "linear":
        raise t.fail("interpolation", 'a processed record is linear between samples; expected "linear"')
    steps = np.diff(times)
    if len(times) < 3 or np.abs(steps - steps.mean()).max() > 1e-9 * steps.mean():
        raise t.fail("baseline" if t.has("baseline") else "filter",
                     "processing needs a uniformly sampled record of at least 3 samples")
    if baseline != "none":
        values = baseline_corrected(times, values, BASELINES[baseline])
    if band is not None:
        low, high = band
        nyquist = 0.5 / steps.mean()
        if not (math.isfinite(low) and math.isfinite(high) and low >= 0 and high >= 0 and (low > 0 or high > 0)
                and (high == 0 or low < high < nyquist) and low < nyquist):
            raise t.fail("filter", f"expected [LOW, HIGH] in Hz, 0 for an open end, LOW < HIGH < the Nyquist "
                                   f"frequency {nyquist:g} Hz, found [{low:g}, {high:g}]")
        if len(times) < 3 * (2 * order + 1):
            raise t.fail("filter", f"{len(times)} samples are too few to filter at order {order}")
        values = band_passed(values, float(steps.mean()), low, high, order)
    return replace(shape, values=tuple(float(v) for v in values))


def _read_table_force(t: _Table) -> dict[str, Any]:
    interpolation = t.string("interpolation", "linear", choices=("linear", "previous"))
    if t.has("file"):
        if t.has("t") or t.has("values"):
            raise t.fail("file", "give either file or t and values, not both")
        times, values, file, file_text, read_as, file_units = _read_file(t, t.string("file"))
    else:
        for key in ("format", "channel", "dt"):
            if t.has(key):
                raise t.fail(key, "describes a record file: expected it with file = ...")
        times = t.numbers("t")
        values = t.numbers("values")
        if len(values) != len(times):
            raise t.fail("values", f"expected {len(times)} numbers (one per entry of t), found {len(values)}")
    if len(times) < 1:
        raise t.fail("t", "expected at least one point")
    steps = np.diff(times)
    if (steps <= 0).any():  # found in one pass: a fit builds its scene again at every trial point
        i = int(np.argmax(steps <= 0)) + 1
        raise t.fail(f"t[{i}]", f"expected strictly increasing times, found {times[i]:g} after {times[i - 1]:g}")
    problem = None if t.has("file") else slope_problem(times, values)
    if problem is not None:
        raise t.fail(f"values[{problem[0]}]", problem[1])
    spec = {"t": times, "values": values, "interpolation": interpolation}
    if t.has("file"):
        spec.update(file=file, file_text=file_text, file_format=read_as, file_units=file_units)
    return spec


def _read_file(t: _Table, name: str) -> tuple[tuple[float, ...], tuple[float, ...], str, str, str, str | None]:
    """(times, values, path, text, format, the unit the file names) of a table's file: two-column text, or a record
    file as `format`, its extension or `dt` say (record_files); values in the file's unit (a COSMOS file's mg as
    g)."""
    from smdcli.scenario.record_files import FORMATS, read_samples

    path = Path(name)
    if not path.is_absolute():
        path = Path(t.file).parent / path
    read_as = t.string("format", choices=FORMATS) if t.has("format") else None
    channel = t.integer("channel", 1, minimum=1) if t.has("channel") else None
    dt = t.number("dt", positive=True) if t.has("dt") else None
    try:
        text = read_text(path)
        samples = read_samples(path, text, read_as, channel, dt)
    except ColumnsError as exc:
        key = str(exc).split(":", 1)[0]
        raise t.fail(key if key in ("format", "channel", "dt") else "file", f"{path}: {exc}") from None
    if samples.units is not None and t.path != "ground_motion":
        raise t.fail("file", f"{path}: an {samples.format.upper()} file holds a ground acceleration; a force's table "
                             "takes two-column or one-column text")
    values = samples.values * samples.factor
    return (tuple(samples.times.tolist()), tuple(values.tolist()), str(path), text, samples.format, samples.units)
