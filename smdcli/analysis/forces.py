"""Element forces of a solved run: the tension in every spring, damper, friction contact and stop on the output
grid, and the ground's reaction on the system.

Sign: an element connecting [a, b] carries the tension T = law(x_b - x_a); it pushes a by +T and b by -T. Summed
over a mass, M a = applied force + the element forces on it (+ [damping]'s force).

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from smdcli.model.elements import Element, incidence_matrix
from smdcli.model.sparse import rows_times
from smdcli.result import ElementForces, moving_columns
from smdcli.scenario import GROUND


ROWS_VALUES = 2 ** 18  # states (rows x DOFs) an element table is computed from at once: its temporaries in cache


def element_stretch(element: Element, q: np.ndarray) -> np.ndarray:
    """An element's stretch d = q_b - q_a (the ground's q zero) of every state in q (..., n): of x for a spring, of v
    for a damper, the d its law reads."""
    return -(q @ incidence_matrix([element], q.shape[-1])[0])


def law_slope(element: Element, d: np.ndarray) -> np.ndarray | float:
    """dT/dd of _tensions' law at the stretch d: c, k + 3 k3 d^2 (cubic) or 2 c |d| (quadratic)."""
    if element.law == "cubic":
        return element.coef + 3 * element.k3 * d**2
    if element.law == "quadratic":
        return 2 * element.coef * np.abs(d)
    return element.coef


def _tensions(elements: list[Element], q: np.ndarray, recorded: dict) -> np.ndarray:
    """(N, elements) tensions of elements of one kind from q (x for springs, v for dampers), a block of rows at a
    time (a 10,000-element chain's table is 80 MB; its temporaries stay a block's); the recorded ones from the run."""
    N = len(q)
    out = np.empty((N, len(elements)))
    if not elements:
        return out
    moving = moving_columns(q)
    if moving is not None:  # zero tension where both ends stay at 0 (a wave's far elements): the others' alone
        index = np.full(q.shape[1] + 1, -1)  # a DOF's column among the moving ones; -1 (the ground's) elsewhere
        index[moving] = np.arange(len(moving))
        live = [j for j, e in enumerate(elements) if index[e.a] >= 0 or index[e.b] >= 0 or e.name in recorded]
        moved = [dataclasses.replace(elements[j], a=int(index[elements[j].a]), b=int(index[elements[j].b]))
                 for j in live]
        out = np.zeros((N, len(elements)))
        out[:, live] = _tensions(moved, q[:, moving], recorded)
        return out
    stretch = incidence_matrix(elements, q.shape[1]).T  # q @ it = q_a - q_b: minus each element's d
    coef = np.array([e.coef for e in elements])
    cubic = np.array([e.k3 if e.law == "cubic" else 0.0 for e in elements])
    quadratic = np.array([e.law == "quadratic" for e in elements])
    nonlinear = cubic.any() if elements[0].kind == "spring" else quadratic.any()
    rows = max(1, ROWS_VALUES // (q.shape[1] + 1))
    for lo in range(0, N, rows):
        if not nonlinear:  # (q_a - q_b) (-c): c d to the bit, in one pass into the table
            np.multiply(rows_times(q[lo:lo + rows], stretch), -coef, out=out[lo:lo + rows])
            continue
        d = -rows_times(q[lo:lo + rows], stretch)  # q_b - q_a, to the bit: the product's two terms, one rounding
        if elements[0].kind == "spring":
            out[lo:lo + rows] = coef * d + cubic * d**3
        else:
            out[lo:lo + rows] = coef * np.where(quadratic, np.abs(d) * d, d)
    for j, e in enumerate(elements):
        if e.name in recorded:
            out[:, j] = recorded[e.name]
    return out


def element_forces(model, x: np.ndarray, v: np.ndarray, history=None) -> ElementForces:
    """Tension in every element and the ground's reaction on the grid; a [system] scene gets -1^T (K x + C v).
    A hysteretic spring's, a friction contact's and a stop's come from the run's history (they depend on the
    path, not on x and v alone)."""
    springs = [e for e in model.elements if e.kind == "spring"]
    dampers = [e for e in model.elements if e.kind == "damper"]
    N = len(x)
    recorded = {} if history is None else {p: history.tension[:, i] for i, p in enumerate(history.paths)}

    spring, damper = _tensions(springs, x, recorded), _tensions(dampers, v, recorded)
    by_kind = {kind: [e for e in model.nonsmooth if e.kind == kind] for kind in ("friction", "stop")}
    laws = {kind: (np.stack([recorded[e.path] for e in found], axis=1) if found else np.zeros((N, 0)))
            for kind, found in by_kind.items()}
    added = None
    if model.element_form:
        reaction = np.zeros(N)
        for elements, table in ((springs, spring), (dampers, damper)):
            for j, e in enumerate(elements):
                if e.b < 0:
                    reaction += table[:, j]  # the ground pushes a by +T
                elif e.a < 0:
                    reaction -= table[:, j]
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
        # 1^T (K x) = (1^T K) x: the columns' sums once, not K x on every row (two 80 MB products on 10,000 DOFs)
        reaction = -(x @ _column_sums(model.K) + v @ _column_sums(model.C))
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


def _column_sums(A) -> np.ndarray:
    """1^T A as a flat array, for a dense or a sparse A."""
    return np.asarray(A.sum(axis=0), dtype=float).ravel()
