"""Where a sensitivity run starts on the edge between two branches of an element (a spring deformed to its yield
point, a contact held at its breakaway force): the parameters whose step moves the start across it have no
derivative there (event_sensitivity.py).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.elements import State
from smdcli.solvers.events.scene import Scene

GRAZE = 1e-9  # a guard's top within this share of its terms below its level: a near miss, no derivative from it


def breakaway_margins(scene: Scene, states, z: np.ndarray) -> np.ndarray:
    """Each stuck contact's force less its breakaway (0 for every other element), in these states at z."""
    from smdcli.elements.friction import STICK

    _, _, tension, _ = scene.evaluate(states, z)
    return np.array([abs(float(tension[e])) - el.law.static
                     if el.kind == "friction" and states[e].mode == STICK and el.law.regularization is None else 0.0
                     for e, el in enumerate(scene.elements)])


def on_breakaway(margins: dict, nominal: np.ndarray, scene: Scene) -> list[str]:
    """The contacts that start held at their breakaway force (within GRAZE of it) and that the parameter's step
    moves off it: on one side each breaks away at once, on the other it holds a while."""
    sizes = np.array([el.law.static if el.kind == "friction" else 0.0 for el in scene.elements])
    on = (np.abs(nominal) <= GRAZE * sizes) & (sizes > 0)
    moved = np.zeros(len(sizes), dtype=bool)
    for m in margins.values():
        moved |= on & (np.abs(m - nominal) > GRAZE * sizes)
    return [el.path for el, edge in zip(scene.elements, moved) if edge]


def kinked(internals: dict, nominal: np.ndarray) -> bool:
    """Whether internal values at stencil points on either side of the nominal one (at 0) slope differently: by a
    tenth or more, where a smooth dependence differs by about the step (1e-3), and a kink (the plastic deformation
    of a spring started at its yield point: zero on one side) by all of it."""
    left = [c for c in internals if c < 0]
    right = [c for c in internals if c > 0]
    if not left or not right or not len(nominal):
        return False
    cl, cr = max(left), min(right)
    slope_left, slope_right = (nominal - internals[cl]) / -cl, (internals[cr] - nominal) / cr
    size = np.maximum(np.abs(slope_left), np.abs(slope_right))
    floor = 1e-9 * (np.abs(nominal) + 1e-300) / min(-cl, cr)
    return bool(np.any((np.abs(slope_right - slope_left) > 0.1 * size) & (size > floor)))


def continuous(internal: dict) -> dict[str, float]:
    """An internal state's numbers that move with the parameters, by name: its real numbers, and each entry of a
    pair of them (a Clough spring's Mahin-Bertero point (d, T)) as name[j]; not its flags and labels (which
    branch a line leads to, whether it runs back), which a small step leaves as they are."""
    found = {}
    for name, value in internal.items():
        if isinstance(value, tuple):
            found.update((f"{name}[{j}]", float(v)) for j, v in enumerate(value))
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            found[name] = float(value)
    return found


def with_continuous(internal: dict, values: dict[str, float]) -> dict:
    """The internal state with its numbers (continuous's names) set to values, its flags and labels as they are."""
    out = dict(internal)
    for name, value in internal.items():
        if isinstance(value, tuple):
            out[name] = tuple(values.get(f"{name}[{j}]", v) for j, v in enumerate(value))
        elif name in values:
            out[name] = values[name]
    return out


def ground_jump(scene: Scene, t: float) -> np.ndarray:
    """The ground's jump of the relative state at t in this scene's model, [dx; dv] (2n,); LookupError where it has
    none there (a pulse the parameter moves in time)."""
    found = [np.concatenate([dx, dv]) for when, dx, dv in scene.model.jumps
             if abs(when - t) <= 1e-12 * max(abs(t), 1.0)]
    if not found:
        raise LookupError
    return np.sum(found, axis=0)


def shifted_states(states, dq: list, i: int, c: float) -> list[State]:
    """The states with their internal variables moved c times their scaled sensitivities to parameter i (dq: each
    element's {name: (P,)}): a stencil point's states along the moved run."""
    return [State(s.mode, with_continuous(s.internal, {name: value + c * float(dq[e][name][i])
                                                       for name, value in continuous(s.internal).items()
                                                       if name in dq[e]})) for e, s in enumerate(states)]


def carry_numbers(run, e: int, names: list[str], expected: State, made) -> bool:
    """The sensitivities of element e's internal numbers `names` that an event (or the ground's jump) sets, into
    run.dq: for each parameter i, run.total of made(scene, c, i), the State the law makes at that stencil point along
    the moved run, read at names. False (the parameters from i on left as they were) where a point's State lies on
    another branch than the nominal `expected`: another mode, other flags or other numbers' names."""
    numbers = continuous(expected.internal)
    for i in range(run.P):
        def at_point(scene, c, i=i):
            state = made(scene, c, i)
            if state.mode != expected.mode or with_continuous(state.internal, numbers) != expected.internal:
                raise _OtherBranch
            found = continuous(state.internal)
            return [found[name] for name in names]
        try:
            values = run.total(i, at_point)
        except _OtherBranch:
            return False
        for name, value in zip(names, values):
            run.dq[e].setdefault(name, np.zeros(run.P))[i] = value
    return True


class _OtherBranch(Exception):
    """A stencil point's event leads to another branch than the nominal one."""


def internal_values(state: State) -> list[float]:
    """A state's internal numbers (continuous's) in name order."""
    numbers = continuous(state.internal)
    return [numbers[name] for name in sorted(numbers)]
