"""Unit strings in a scenario's numeric fields: "25 N/mm", "3 t", "0.35 g", "2 Hz", "5 %" converted to the field's SI
unit with pint, and refused when their dimension is another ("expected a stiffness (force/length), found a mass").

pint is imported only when a scene holds a unit string: its import and registry cost 0.7 s, which a scene written in
plain SI numbers never pays.

Must not import: model, solvers, or any layer above."""

from __future__ import annotations

import math
import re
from functools import lru_cache

# A field's SI unit by its key, where the key alone says it. An element law's keys are in its class's `units`; a
# reader names the unit itself where a key has two meanings (Rayleigh alpha in 1/s against Bouc-Wen's dimensionless
# alpha), and a table's context sets it where the context decides (a force's amplitude against a ground
# displacement's).
FIELD_UNITS = {"m": "kg", "M": "kg", "k": "N/m", "K": "N/m", "c": "N s/m", "C": "N s/m", "k3": "N/m^3",
               "x0": "m", "v0": "m/s", "start": "s", "end": "s", "step": "s", "dt": "s", "t": "s", "t0": "s",
               "t1": "s", "duration": "s", "period": "s", "tail": "s", "omega": "rad/s", "frequency": "Hz",
               "f0": "Hz", "f1": "Hz", "phase": "rad", "duty": "1", "zeta": "1", "modal": "1", "rtol": "1",
               "atol": "m", "scale": "1", "im_tolerance": "1", "storey_heights": "m", "filter": "Hz"}

# What each SI unit measures, in the words an error message uses ("expected a stiffness (force/length)").
_MEASURES = {"N/m": "a stiffness (force/length)", "N s/m": "a damping coefficient (force/velocity)",
             "N s^2/m^2": "a quadratic damping coefficient (force/velocity^2)",
             "N/m^3": "a cubic stiffness (force/length^3)", "kg": "a mass", "m": "a length", "m/s": "a velocity",
             "m/s^2": "an acceleration", "N": "a force", "s": "a time", "Hz": "a frequency",
             "rad/s": "an angular frequency", "rad": "an angle", "1": "a ratio (dimensionless)",
             "1/s": "a rate (1/time)",
             "J": "an energy", "Pa": "a pressure (force/area)", "m^2": "an area", "m^3": "a volume", "W": "a power",
             "kg m^2": "a moment of inertia", "N m": "a moment (force x length)", "K": "a temperature"}

_NUMBER = re.compile(r"\s*([+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)\s*(.*?)\s*")
# On an acceleration field g is standard gravity, not a gram, and gal is the galileo (cm/s^2), not the gallon.
_GRAVITY_WORDS = {"g": "g_0", "mg": "smd_milli_g", "gal": "Gal"}


def measure(unit: str) -> str:
    """What an SI unit measures, in words: 'N/m' -> 'a stiffness (force/length)'."""
    return _MEASURES.get(unit, f"a quantity in {unit}")


_EXAMPLES = {"N/m": "25 N/mm", "kg": "3 t", "m/s^2": "0.35 g", "rad/s": "2 Hz", "Hz": "2 Hz", "1": "5 %", "N": "10 kN",
             "m": "25 mm", "s": "20 ms", "rad": "90 deg", "N s/m": "2 kN s/m", "m/s": "30 cm/s"}


def example(unit: str) -> str:
    """A unit string a user could write for such a field: '25 N/mm'."""
    return _EXAMPLES.get(unit, f"1 {unit}")


class UnitError(ValueError):
    """A unit string that is not a number and a unit of the field's dimension; the message says what was found."""


@lru_cache(maxsize=1)
def _registry():
    import pint

    registry = pint.UnitRegistry()
    registry.define("smd_milli_g = 1e-3 * standard_gravity")  # mg on an acceleration field, as COSMOS records use it
    return registry


def _pint_unit(unit: str) -> str:
    """An SI unit as this module writes it ('N s/m', 'm/s^2') in pint's syntax."""
    return unit.replace("^", "**").replace(" ", " * ")


def to_si(text: str, unit: str) -> float:
    """The value of "<number> <unit>" in the field's SI `unit`; a plain number string on a dimensionless field.
    An angular frequency takes Hz as cycles per second (2 Hz = 4 pi rad/s), a frequency takes rad/s as radians
    (2 pi rad/s = 1 Hz)."""
    match = _NUMBER.fullmatch(text)
    if not match:
        raise UnitError(f'expected {measure(unit)} as a number or "<number> <unit>" (e.g. "{example(unit)}"), '
                        f"found {text[:40]!r}")
    number, written = float(match.group(1)), match.group(2)
    if not written:
        if unit in ("1", ""):
            return number
        raise UnitError(f'expected {measure(unit)}: a number in {unit} or a string with its unit (e.g. '
                        f'"{example(unit)}"), found {text[:40]!r} with no unit')
    if unit == "m/s^2":
        written = re.sub(r"\b(g|mg|gal)\b", lambda m: _GRAVITY_WORDS[m.group(1)], written)
    ureg = _registry()
    import pint

    try:
        given = ureg.parse_units(written.replace("^", "**"))
    except Exception as exc:  # pint's parser raises its own errors, and AssertionError on '1 m**'
        detail = f": unknown unit {exc.unit_names!r}" if isinstance(exc, pint.errors.UndefinedUnitError) and \
            isinstance(getattr(exc, "unit_names", None), str) else ""
        raise UnitError(f"expected {measure(unit)}, found {text[:40]!r}, whose unit cannot be read{detail}") from None
    target = ureg.parse_units(_pint_unit(unit)) if unit not in ("1", "") else ureg.dimensionless
    if given.dimensionality != target.dimensionality:
        raise UnitError(f"expected {measure(unit)}, found {_found(ureg, given)} ({text[:40]!r})")
    try:
        value = float(ureg.Quantity(number, given).to(target).magnitude)
    except pint.errors.PintError as exc:  # an offset unit (degC) in a product, say
        raise UnitError(f"expected {measure(unit)}, found {text[:40]!r}: {exc}") from None
    names = given._units.keys()
    cycles = any(name.endswith("hertz") for name in names)
    angles = "radian" in str(ureg.get_root_units(given)[1])
    if unit == "rad/s" and cycles:
        value *= 2 * math.pi  # pint holds radians dimensionless, so Hz -> rad/s would keep the number
    elif unit == "Hz" and angles:
        value /= 2 * math.pi
    return value


def _found(ureg, given) -> str:
    """What a parsed unit measures, in words ('a mass'), or its base units when it is none of the known measures."""
    angles = "radian" in str(ureg.get_root_units(given)[1])
    for unit, words in _MEASURES.items():
        if unit in ("1", "rad") and given.dimensionality == ureg.dimensionless.dimensionality:
            return "an angle" if angles else "a ratio (dimensionless)"
        if unit in ("Hz", "rad/s", "1/s"):
            continue
        if ureg.parse_units(_pint_unit(unit)).dimensionality == given.dimensionality:
            return words
    if given.dimensionality == ureg.parse_units("1/s").dimensionality:
        return "a frequency"
    return f"a quantity in {ureg.Quantity(1, given).to_base_units().units:~}"
