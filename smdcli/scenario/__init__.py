"""Scenario layer: TOML -> frozen, validated Scenario. Nothing numeric is computed here.

Every error names the file and the field path (``spring[2].k``); TOML syntax errors name the line.
Unknown keys are errors, named before anything they leave missing, with the key they most likely mean.

Modules: spec (the dataclasses), reader (one table's typed fields), load (file or text -> Scenario),
structure, forces, options (the tables). Must not import: model, solvers (a
method's name and options are checked by smdcli.solvers.run), sweep, io, plots, commands, cli.
"""

from smdcli.scenario.load import load, parse, parse_document
from smdcli.scenario.options import SWEEP_KEYS
from smdcli.scenario.reader import read_regular_file
from smdcli.scenario.spec import (DEFAULT_POINTS, FORCE_TYPES, GROUND, MAX_SAMPLES, ElementSpec, ForceSpec,
                                  GroundMotionSpec, MassSpec, MatrixSystem, Scenario, SolverSpec, TimeSpec)

__all__ = ["DEFAULT_POINTS", "FORCE_TYPES", "GROUND", "MAX_SAMPLES", "SWEEP_KEYS", "ElementSpec", "ForceSpec",
           "GroundMotionSpec", "MassSpec", "MatrixSystem", "Scenario", "SolverSpec", "TimeSpec", "load", "parse", "parse_document",
           "read_regular_file"]
