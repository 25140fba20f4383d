"""A linear scene's model with one number moved (a mass, a spring's k, a damper's c, an initial displacement or
velocity, Rayleigh's alpha or beta, a force's amplitude, frequency, phase, duty or sweep), assembled from the model
it was built as instead of from the scenario again: what a parameter's derivative takes at each point of its
stencil, at a hundredth of a build's cost.

The numbers change where build would put them: a mass on M's diagonal, an element's k or c stamped between its
two ends, [damping]'s part of C made again from the moved M and K or coefficient (Rayleigh's alpha M + beta K, or
the modal damping of the moved modes), the ground's jumps from the moved M and C (Model.with_matrices), the
element's own coefficient (its tension reads it), and a force made again from its spec.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

from smdcli.model.damping import added_damping
from smdcli.model.elements import incidence_row
from smdcli.model.system import Model
from smdcli.scenario import Scenario
from smdcli.shapes import build_signal
from smdcli.shapes.registry import SHAPES
from smdcli.shapes.table import Table

_PATH = re.compile(r"mass(?:\.(?P<name>[^.\[\]]+)|\[(?P<index>\d+)\])\.(?P<field>m|x0|v0)"
                   r"|(?P<element>spring\[\d+\]\.k|damper\[\d+\]\.c)|damping\.(?P<rayleigh>alpha|beta)"
                   r"|force\[(?P<force>\d+)\]\.(?P<key>amplitude|omega|frequency|period|phase|duty|f0|f1|t1)")
_NO_AMPLITUDE = ("table", "expression")  # force types whose amplitude is not what their numbers are made from


def moved(model: Model, scenario: Scenario, path: str, value: float) -> Model | None:
    """The model with the number at path set to value (SI), or None where only build can say (a nonlinear scene, a
    [system] or sparse one, a path that is not a mass's, a linear spring's k, a linear damper's c, Rayleigh's
    alpha or beta or a force's number, a table's or an expression's)."""
    found = _PATH.fullmatch(path)
    if found is None or not model.is_linear or not model.element_form or model.is_sparse:
        return None
    if found["force"] is not None:  # the force made again from its spec with the number moved
        index = int(found["force"])
        if index >= len(scenario.forces) or scenario.forces[index].type in _NO_AMPLITUDE:
            return None
        key, spec = found["key"], scenario.forces[index]
        if key not in SHAPES[spec.type].fields:
            return None  # a number this force's type does not read: build refuses it
        if key in ("frequency", "period"):  # the spec holds them as omega, in rad/s
            if value <= 0:
                return None
            key, value = "omega", 2 * math.pi * value if key == "frequency" else 2 * math.pi / value
        if not isinstance(getattr(spec, key), float):
            return None  # not given as a number (a field the reader resolves otherwise): build says what
        signal = build_signal(dataclasses.replace(spec, **{key: value}))
        return dataclasses.replace(model, signals=model.signals[:index] + (signal,) + model.signals[index + 1:])
    if value < 0 or value == 0 and found["field"] == "m":
        return None  # not a scene: build refuses it, and the stencil turns one-sided
    if found["rayleigh"]:  # Rayleigh's coefficient as the scenario gives it (not through zeta at two frequencies)
        spec = scenario.damping
        if spec is None or spec.modal or spec.given not in ("alpha", "beta"):
            return None
        damped = dataclasses.replace(scenario, damping=dataclasses.replace(spec, **{found["rayleigh"]: value}))
        return _damped(model, damped, model.M, model.C, model.K)
    if found["element"]:
        name, _, key = found["element"].partition(".")
        element = next((e for e in model.elements if e.name == name and e.law == "linear"), None)
        if element is None:
            return None
        row = incidence_row(element.connects, {dof: i for i, dof in enumerate(model.dofs)}, model.n)
        change = (value - element.coef) * np.outer(row, row)  # the element's stamp between its two ends
        M, C, K = model.M, model.C, model.K
        if key == "k":
            K = K + change
        else:
            C = C + change
        elements = tuple(dataclasses.replace(e, coef=value) if e is element else e for e in model.elements)
        return _damped(model, scenario, M, C, K, elements=elements)
    if found["name"] is not None and found["name"] not in model.dofs:
        return None
    index = model.dofs.index(found["name"]) if found["name"] is not None else int(found["index"])
    if index >= model.n:
        return None
    if found["field"] != "m":
        start = getattr(model, found["field"]).copy()
        start[index] = value
        return dataclasses.replace(model, **{found["field"]: start})
    M = model.M.copy()
    M[index, index] = value
    return _damped(model, scenario, M, model.C, model.K)


def scaled_ground(model: Model, table: dict, current: float, value: float) -> Model | None:
    """The model with its recorded ground acceleration's scale moved from current to value: the record's samples
    times value / current (its processing, a baseline's and a filter's, is linear in them), where its table (the
    scenario's [ground_motion], as decoded) adds no shift; None where build must say (another motion, a shift, a
    scale of 0, a value that overflows)."""
    ground = model.ground
    if ground is None or not ground.record or ground.jumps or current == 0 or table.get("shift", 0) != 0:
        return None
    record = ground.acceleration
    values = record.v * (value / current)
    if not np.isfinite(values).all():
        return None
    scaled = Table(record.t, values, "previous" if record.previous else "linear", ended=record.ended)
    signals = tuple(scaled if s is record else s for s in model.signals)
    moved_ground = dataclasses.replace(ground, given=scaled if ground.given is record else ground.given,
                                       acceleration=scaled)
    return dataclasses.replace(model, signals=signals, ground=moved_ground)


def _damped(model: Model, scenario: Scenario, M: np.ndarray, C: np.ndarray, K: np.ndarray, **changes) -> Model:
    """The model with M, C and K moved, [damping]'s part of C made again from the moved M and K."""
    extra = model.added_damping
    if scenario.damping is not None:
        extra = added_damping(scenario, M, K)
        C = C - model.added_damping + extra
    return model.with_matrices(M=M, C=C, K=K, added_damping=extra, **changes)
