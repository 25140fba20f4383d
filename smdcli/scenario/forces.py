"""[[force]] tables: every force type's fields, table forces read from files.

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
                                     slope_problem, two_columns)
from smdcli.scenario.spec import FORCE_TYPES, GROUND, GROUND_QUANTITIES, GROUND_UNITS, ForceSpec, GroundMotionSpec

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
    omega = value if key == "omega" else 2 * math.pi * value if key == "frequency" else 2 * math.pi / value
    if not math.isfinite(omega):  # 2 pi f past 1.8e308, or a period below 3.5e-308
        raise t.fail(key, f"expected an angular frequency below 1.8e308 rad/s, found {key} = {value:g} "
                          f"({'2 pi f' if key == 'frequency' else '2 pi / period'} overflows)")
    return omega


def _read_force(t: _Table, index: int, dofs: tuple[str, ...]) -> ForceSpec:
    on = t.string("on")
    if on not in dofs:
        hint = difflib.get_close_matches(on, dofs, n=1)
        extra = f" (did you mean {hint[0]!r}?)" if hint else f"; DOFs are {', '.join(dofs)}"
        raise t.fail("on", f"unknown DOF {on!r}{extra}")
    return _read_shape(t, index, on, ("on",))


def _read_shape(t: _Table, index: int, on: str, others: tuple[str, ...]) -> ForceSpec:
    """A force shape: `type` and the keys it takes; `others` are the table's keys read elsewhere."""
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
        if spec["t0"] + spec["duration"] == spec["t0"]:
            raise t.fail("duration", f"expected a duration that moves the time t0 = {spec['t0']:g} s, found "
                                     f"{spec['duration']:g} s, below its rounding ({math.ulp(spec['t0']):.3g} s)")
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
    t.finish(others + ("type",) + _FORCE_FIELDS[kind])
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
    factor = allowed[units]
    if shape.type == "table":
        shape = replace(shape, values=tuple((v * scale + shift) * factor for v in shape.values))
        if baseline != "none" or band is not None:
            shape = _processed(t, shape, baseline, band, order)
    elif shape.type == "expression":
        if factor != 1.0:
            shape = replace(shape, expr=f"({shape.expr}) * {factor!r}")
    else:
        shape = replace(shape, amplitude=shape.amplitude * factor)
    si_units = next(u for u, f in allowed.items() if f == 1.0)
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
    problem = None if t.has("file") else slope_problem(times, values)
    if problem is not None:
        raise t.fail(f"values[{problem[0]}]", problem[1])
    spec = {"t": times, "values": values, "interpolation": interpolation}
    if t.has("file"):
        spec.update(file=file, file_text=file_text)
    return spec


def _read_csv(t: _Table, name: str) -> tuple[tuple[float, ...], tuple[float, ...], str, str]:
    csv_path = Path(name)
    if not csv_path.is_absolute():
        csv_path = Path(t.file).parent / csv_path
    try:
        text = read_text(csv_path)
        times, values = two_columns(text)
    except ColumnsError as exc:
        raise t.fail("file", f"{csv_path}: {exc}") from None
    return times, values, str(csv_path), text
