"""Element forces of a solved run: the tension in every spring, damper, friction contact and stop on the output
grid, and the ground's reaction on the system.

Sign: an element connecting [a, b] carries the tension T = law(x_b - x_a); it pushes a by +T and b by -T. Summed
over a mass, M a = applied force + the element forces on it (+ [damping]'s force).

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.model.elements import Element
from smdcli.result import ElementForces
from smdcli.scenario import GROUND


def _stretch(q: np.ndarray, element: Element) -> np.ndarray:
    """q_b - q_a on the grid, the ground's q being 0."""
    zero = np.zeros(len(q))
    return (q[:, element.b] if element.b >= 0 else zero) - (q[:, element.a] if element.a >= 0 else zero)


def tension(element: Element, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The element's force, positive in tension, (N,)."""
    if element.kind == "spring":
        d = _stretch(x, element)
        return element.coef * d + (element.k3 * d**3 if element.law == "cubic" else 0.0)
    dv = _stretch(v, element)
    return element.coef * (np.abs(dv) * dv if element.law == "quadratic" else dv)


def element_forces(model, x: np.ndarray, v: np.ndarray, history=None) -> ElementForces:
    """Tension in every element and the ground's reaction on the grid; a [system] scene gets -1^T (K x + C v).
    A hysteretic spring's, a friction contact's and a stop's come from the run's history (they depend on the
    path, not on x and v alone)."""
    springs = [e for e in model.elements if e.kind == "spring"]
    dampers = [e for e in model.elements if e.kind == "damper"]
    N = len(x)
    recorded = {} if history is None else {p: history.tension[:, i] for i, p in enumerate(history.paths)}

    def table(elements):
        columns = [recorded[e.name] if e.name in recorded else tension(e, x, v) for e in elements]
        return np.stack(columns, axis=1) if columns else np.zeros((N, 0))

    spring, damper = table(springs), table(dampers)
    by_kind = {kind: [e for e in model.nonsmooth if e.kind == kind] for kind in ("friction", "stop")}
    laws = {kind: (np.stack([recorded[e.path] for e in found], axis=1) if found else np.zeros((N, 0)))
            for kind, found in by_kind.items()}
    added = None
    if model.element_form:
        reaction = np.zeros(N)
        for e, column in zip(springs + dampers, np.concatenate([spring, damper], axis=1).T):
            if e.b < 0:
                reaction += column  # the ground pushes a by +T
            elif e.a < 0:
                reaction -= column
        for kind, found in by_kind.items():
            for e, column in zip(found, laws[kind].T):
                if e.connects[1] == GROUND:
                    reaction += column
                elif e.connects[0] == GROUND:
                    reaction -= column
        meaning = "the sum of the forces of the elements attached to the ground on the masses"
        if model.added_damping is not None:
            added = -(v @ model.added_damping.T)
            meaning += " ([damping]'s force, in added_damping_force, not included)"
    else:
        reaction = -(x @ model.K.T + v @ model.C.T).sum(axis=1)
        meaning = ("-1^T (K x + C v): a [system] scene has no elements; this is the ground's reaction where K and C "
                   "are assembled from two-terminal elements (internal forces cancel in the sum)")
    extra = {}
    if model.nonsmooth:
        extra = dict(friction=laws["friction"], friction_names=tuple(e.path for e in by_kind["friction"]),
                     friction_connects=tuple(e.connects for e in by_kind["friction"]), stop=laws["stop"],
                     stop_names=tuple(e.path for e in by_kind["stop"]),
                     stop_connects=tuple(e.connects for e in by_kind["stop"]),
                     internal=dict(history.internal) if history is not None else {})
    return ElementForces(spring, damper, tuple(e.name for e in springs), tuple(e.name for e in dampers),
                         tuple(e.connects for e in springs), tuple(e.connects for e in dampers), reaction, meaning,
                         added, model.element_form, **extra)
