"""The scenario format's JSON Schema, whole: the scenario layer's tables with the solvers' registry's methods and
options.

Must not import: cli.
"""

from __future__ import annotations

from smdcli.scenario.schema import scenario_schema
from smdcli.solvers.registry import NAMES, solver_options_schema


def full_schema() -> dict:
    """The JSON Schema that `smd schema` prints."""
    schema = scenario_schema()
    properties = schema["properties"]
    properties["solver"] = solver_options_schema()
    properties["sweep"]["properties"]["method"] = {"enum": list(NAMES)}
    return schema
