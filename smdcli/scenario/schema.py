"""A JSON Schema (draft 2020-12) of the scenario format, for editors: built from the tables of keys, laws, force
types, methods and choices that the reader validates with, so that a key the reader learns is in the schema.

What the schema checks is the structure: the tables, their keys (no other), each value's type, the choices. What
it cannot say (a spring between two masses that exist, end after start, a positive-definite M) only smd checks.

The [solver] table's methods and options are the solvers' registry's: smdcli.commands.schema puts them in.

Must not import: model, solvers, or any layer above."""

from __future__ import annotations

from smdcli.elements.registry import SPRING_LAWS, TABLES
from smdcli.scenario.forces import _ANY_FORCE_KEYS, GROUND_KEYS
from smdcli.scenario.options import EXPECT_KEYS, FIT_KEYS, IDA_KEYS, OPTIMIZE_KEYS, SOLVER_KEYS, SWEEP_KEYS
from smdcli.scenario.reader import _MASS_KEYS, _SYSTEM_KEYS, _TIME_KEYS, _TOP_KEYS
from smdcli.scenario.record_files import FORMATS
from smdcli.scenario.spec import EXPECT_QUANTITIES, FORCE_TYPES, GROUND_QUANTITIES, GROUND_UNITS
from smdcli.scenario.structure import BUILDING_KEYS, DAMPING_KEYS
from smdcli.shapes.registry import SHAPES

PLAIN_NUMBER = {"type": "number"}
# a measured field: a number in SI or "<number> <unit>" (smd converts it with pint and checks its dimension)
NUMBER = {"anyOf": [PLAIN_NUMBER, {"type": "string", "pattern": r"^\s*[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?(\s*\S.*)?$",
                                   "description": 'a number with its unit, e.g. "25 N/mm", "3 t", "0.35 g", "2 Hz", '
                                                  '"5 %"'}]}
INTEGER = {"type": "integer"}
STRING = {"type": "string"}
BOOLEAN = {"type": "boolean"}
NUMBERS = {"type": "array", "items": NUMBER}
STRINGS = {"type": "array", "items": STRING}
MATRIX = {"type": "array", "items": NUMBERS}
MATRIX_OR_FILE = {"anyOf": [MATRIX, {**STRING, "description": "a .mtx, .npz or .mat file, relative to the scenario"}]}
CONNECTS = {"type": "array", "items": STRING, "minItems": 2, "maxItems": 2,
            "description": "two different nodes: mass names or \"ground\""}

# The keys whose values are not plain numbers; every other key of a table is a number.
SPECIAL = {
    "title": STRING, "description": STRING, "name": STRING, "connects": CONNECTS, "on": STRING,
    "type": {"enum": list(FORCE_TYPES)}, "expr": STRING, "file": STRING, "t": NUMBERS,
    "values": {"anyOf": [NUMBERS, STRING, {"type": "array", "items": {"anyOf": [NUMBERS, STRING]}}]},
    "interpolation": {"enum": ["linear", "previous"]}, "terms": INTEGER, "points": INTEGER, "mode": INTEGER,
    "dofs": STRINGS, "M": MATRIX_OR_FILE, "C": MATRIX_OR_FILE, "K": MATRIX_OR_FILE, "method": STRING,
    "parameter": {"anyOf": [STRING, STRINGS]}, "labels": STRINGS,
    "ic": STRINGS, "frequency": {"anyOf": [NUMBER, STRING]}, "normalized": BOOLEAN, "input": STRING,
    "direction": {"enum": ["up", "down", "both"]}, "measure": BOOLEAN, "metric": STRING,
    "omega": {"anyOf": [NUMBER, NUMBERS]}, "modal": {"anyOf": [NUMBER, NUMBERS]},
    "units": {"enum": sorted({u for units in GROUND_UNITS.values() for u in units} | {"g"})},
    "dof": STRING, "baseline": {"enum": ["none", "linear", "quadratic"]}, "filter": {**NUMBERS, "minItems": 2, "maxItems": 2},
    "filter_order": INTEGER, "hold": BOOLEAN, "format": {"enum": list(FORMATS)},
    "channel": INTEGER,
} | {key: schema for shape in SHAPES.values() for key, schema in shape.schema.items()}


def _table(keys, required=(), **overrides) -> dict:
    """An object of exactly these keys, numbers unless SPECIAL or `overrides` say otherwise."""
    return {"type": "object", "additionalProperties": False, "required": list(required),
            "properties": {k: overrides.get(k, SPECIAL.get(k, NUMBER)) for k in keys}}


def _array_of(table: dict) -> dict:
    return {"type": "array", "items": table}


def scenario_schema() -> dict:
    """The JSON Schema of a scenario TOML document (as JSON: TOML's tables are objects, its arrays arrays), with the
    [solver] table's own keys only and any method name (the registry's are added above)."""
    spring_keys = ("connects", "k", "law", "k3") + tuple(
        dict.fromkeys(k for law in SPRING_LAWS.values() for k in law.keys if k != "k"))
    arrays = {key: {"anyOf": [NUMBER, NUMBERS]} for law in SPRING_LAWS.values() for key in law.arrays}
    spring = _table(spring_keys, ["connects"], law={"enum": ["linear", "cubic", *SPRING_LAWS]}, **arrays)
    damper = _table(("connects", "c", "law"), ["connects", "c"], law={"enum": ["linear", "quadratic"]})
    contacts = {name: _table(("connects",) + law.keys, ["connects"]) for name, law in TABLES.items()}
    a_force = {"frequency": NUMBER, "omega": NUMBER, "values": NUMBERS}  # as a force has them (a sweep differs)
    force = _table(_ANY_FORCE_KEYS, ["on", "type"], **a_force)
    ground = _table(GROUND_KEYS, ["quantity", "type"], quantity={"enum": list(GROUND_QUANTITIES)}, **a_force)
    properties = {
        "title": STRING, "description": STRING,
        "time": _table(_TIME_KEYS, ["end"]),
        "mass": _array_of(_table(_MASS_KEYS, ["name", "m"])),
        "spring": _array_of(spring), "damper": _array_of(damper),
        "friction": _array_of(contacts["friction"]), "stop": _array_of(contacts["stop"]),
        "system": {**_table(_SYSTEM_KEYS, ["M", "K"], x0=NUMBERS, v0=NUMBERS),  # dofs: x1..xn where M is a file
                   "if": {"properties": {"M": {"type": "array"}}, "required": ["M"]}, "then": {"required": ["dofs"]}},
        "force": _array_of(force),
        "solver": _table(SOLVER_KEYS),
        "sweep": _table(SWEEP_KEYS, quantity={"enum": ["displacement", "velocity", "acceleration", "force"]}),
        "damping": _table(DAMPING_KEYS, omega={**NUMBERS, "minItems": 2, "maxItems": 2}),
        "ground_motion": ground,
        "expect": _array_of(_table(EXPECT_KEYS, ["quantity"], quantity={"enum": list(EXPECT_QUANTITIES)})),
        "fit": _table(FIT_KEYS, data=STRING, parameters={"anyOf": [STRING, STRINGS]}, channels=STRINGS,
                      bounds={"type": "object", "additionalProperties": {**NUMBERS, "minItems": 2, "maxItems": 2}},
                      weights={"type": "object", "additionalProperties": PLAIN_NUMBER}),
        "ida": _table(IDA_KEYS, records={"anyOf": [STRING, STRINGS]}, im=STRING, edp=STRING, collapse=STRING,
                      runs={"type": "integer", "minimum": 0}),
        "building": _table(BUILDING_KEYS, ("storey_heights",), storey_heights=NUMBERS, masses=STRINGS),
        "optimize": _table(OPTIMIZE_KEYS, minimize=STRING, subject_to={"anyOf": [STRING, STRINGS]}, input=STRING,
                           input_psd=STRING, psd_units={"enum": ["g", "m/s^2"]},
                           starts={"type": "integer", "minimum": 1},
                           parameters={"type": "object",
                                       "additionalProperties": {**NUMBERS, "minItems": 2, "maxItems": 2}}),
    }
    assert set(properties) == set(_TOP_KEYS), "every top-level table the reader knows is described"
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "https://smd.invalid/scenario-1.schema.json",
        "title": "smd scenario (TOML, version 1)",
        "description": "A spring-mass-damper scene for `smd simulate`. Structure only: smd checks the rest.",
        "type": "object", "additionalProperties": False, "required": ["time"],
        "properties": properties,
        "oneOf": [{"required": ["mass"], "not": {"required": ["system"]}},
                  {"required": ["system"], "not": {"anyOf": [{"required": [k]} for k in
                                                             ("mass", "spring", "damper", "friction", "stop")]}}],
    }
