"""A yielding, friction or stop element's own law keys as parameters (`spring[0].fy`, `friction[0].force`,
`stop[0].max`): which element and key a path names, and the scene with the key moved where only the law reads it.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import re

from smdcli.model import Model
from smdcli.model.nonsmooth import check_initial_state
from smdcli.scenario import Scenario
from smdcli.scenario.structure import read_law

LAW_KEY = re.compile(r"(?P<kind>spring|friction|stop)\[(?P<index>\d+)\]\.(?P<key>\w+)")  # a law's own key


def law_moved(sc: Scenario, doc: dict, base: Model, path: str, value: float) -> Model | None:
    """The scene with a law's key at value where only the law reads it (a yield force, a gap): the law read again by
    the scenario reader's checks (ScenarioError where it is no scene), the matrices kept (a record's scene six builds
    faster); None where the matrices or the belt move with the key (a spring's k, a belt's speed): build says."""
    element, key = law_key(base, path)
    if element is None:
        return None
    kind, index = element.path.rstrip("]").split("[")
    item = dict(doc[kind][int(index)])
    item[key] = float(value)
    law = read_law(sc.path, kind, int(index), item)
    if beside_law(law) != beside_law(element.law):
        return None
    nonsmooth = tuple(dataclasses.replace(e, law=law) if e is element else e for e in base.nonsmooth)
    check_initial_state(sc, nonsmooth, base.x0)
    return dataclasses.replace(base, nonsmooth=nonsmooth)


def law_key(base: Model, path: str) -> tuple:
    """(the element, its law's key) a path names (`friction[0].force`), or (None, None)."""
    found = LAW_KEY.fullmatch(path)
    element = found and next((e for e in base.nonsmooth if e.path == f"{found['kind']}[{found['index']}]"), None)
    return (element, found["key"]) if element and found["key"] in type(element.law).keys else (None, None)


def beside_law(law) -> tuple[float, float, float]:
    """What of a law the model holds outside it: the stiffness stamped into K, the one [damping] sees at rest, the
    belt's speed under a contact (model.nonsmooth's belt)."""
    return law.elastic_stiffness, law.linear_stiffness, float(getattr(law, "belt_velocity", 0.0))
