"""Where a sensitivity run starts on the edge between two branches of an element (a spring deformed to its yield
point, a contact held at its breakaway force): the parameters whose step moves the start across it have no
derivative there (event_sensitivity.py).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.analysis.signal_derivative import stencil_total
from smdcli.elements import State
from smdcli.solvers.events.scene import Scene
from smdcli.solvers.ground import jump_at

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


def start_derivative(scene: Scene, stencil: tuple, scale: float, t: float, states, nominal: np.ndarray,
                     held_margins: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """The start's scaled derivative along a stencil ([z0; the elements' internal values], from each point's
    own start), and the elements whose start the stencil's step moves across an edge between two branches
    (none where it does not)."""
    n = scene.model.n
    branches, internals = set(), {}  # the elements' starting modes and internal values at the stencil's points
    margins = {}  # the held contacts' forces less their breakaway at the stencil's points
    ragged = []  # the points whose internal variables are another branch's

    def initial(point, c):
        model = point.model
        z0 = np.zeros(point.size)
        z0[:n], z0[n:2 * n] = model.x0, model.v0
        point.reseed(z0, t)
        d0, rate0 = point.R @ model.x0, point.R @ model.v0 + point.belts
        starts = [el.law.start(float(d0[e]), float(rate0[e])) for e, el in enumerate(point.elements)]
        branches.add(tuple(s.mode for s in starts))
        margins[c] = breakaway_margins(point, starts, z0)
        internals[c] = np.array([value for s in starts for value in internal_values(s)])
        if len(internals[c]) != len(nominal):
            # another branch, whose internal variables differ in number (a Clough spring deformed to its
            # yield point exactly, the stiffness moved: elastic on one side, on its backbone on the other)
            ragged.append(c)
            internals[c] = np.full(len(nominal), np.nan)
        return np.concatenate([z0, internals[c]])
    flat = stencil_total(stencil, scale, initial)
    held_at_breakaway = on_breakaway(margins, held_margins, scene)
    if not (len(branches) > 1 or ragged or kinked(internals, nominal) or held_at_breakaway):
        return flat, []
    return flat, (held_at_breakaway or
                  [el.path for k, el in enumerate(scene.elements) if len({b[k] for b in branches}) > 1] or
                  [el.path for el, state in zip(scene.elements, states) if state.internal])


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


def jumped_state(scene: Scene, states, z: np.ndarray, t: float, v_scale: float) -> tuple[list[State], np.ndarray]:
    """The ground's jump at t from (states, z) in this scene, as PiecewiseRun.cross_break makes it, nothing recorded:
    the state jumped (ground.jump_at), each element's state by its law's own jump, a rigid stop the jump drives into
    the mass resting on it struck (its rebound; held again where it has none), the modes decided anew at the new
    state (consistent: a stuck contact the jump sets slipping, a stop it leaves behind let go) and the state put on
    the held constraints (project)."""
    from smdcli.elements.stop import FREE
    from smdcli.solvers.events.decisions import consistent, driven_into, impact, project
    from smdcli.solvers.events.scene import TOUCH

    n = scene.n
    z = z.copy()
    d_old = scene.R @ z[:n]
    z[:2 * n] += jump_at(scene.model, t)
    d_new = scene.R @ z[:n]
    states = [el.law.jump(state, float(d_old[e]), float(d_new[e]))[0]
              for e, (el, state) in enumerate(zip(scene.elements, states))]
    for e in driven_into(scene, states, z, TOUCH * v_scale):
        law = scene.elements[e].law
        states[e] = State(FREE)
        z = impact(scene, states, z, e, law.rebound)
        if law.rebound == 0:
            states[e] = law.event(states[e], "rest", float(d_new[e]), 0.0, 0.0)
    states = consistent(scene, states, z, t, lambda e, kind: None, (), v_scale, ())
    return states, project(scene, states, z, v_scale)


def across_ground_jump(run, t: float, before, after, z: np.ndarray, moved, reseed: bool = False) -> np.ndarray | str:
    """The state's scaled sensitivities [dx; dv] (P, 2n) just after the ground's jump at t, each the total derivative
    of jumped_state along its parameter at the stencil's points (the jump's own derivative, a mass's or a damper's
    impulse c du, an impact's rebound, a contact's constraint where it stays held), with the elements' internal
    numbers that the jump sets carried into run.dq (a spring yielding through a displacement step); or why there is
    none (a jump the parameter moves in time, modes it decides otherwise within the parameter's step). run: a
    sensitivity run (its n, P, dq, v_scale, total); before, after: the modes on either side; z: the state just
    before, moved(i) its sensitivity to parameter i (z's size); reseed: the force generators in z, restarted at t by
    each scene."""
    n, modes = run.n, [state.mode for state in after]

    def mapped(scene, c, i):
        start = z + c * moved(i)
        if reseed:
            scene.reseed(start, t)
        return jumped_state(scene, shifted_states(before, run.dq, i, c), start, t, run.v_scale)

    def on_branch(scene, c, i):
        states, jumped = mapped(scene, c, i)
        if [state.mode for state in states] != modes:
            raise _OtherBranch
        return jumped[:2 * n]
    try:
        rows = np.array([run.total(i, lambda scene, c, i=i: on_branch(scene, c, i)) for i in range(run.P)])
    except LookupError:
        return "the ground's jump moves in time with the parameter"
    except _OtherBranch:
        return "the elements' modes after the ground's jump change within the parameter's step"
    for e, (old, new) in enumerate(zip(before, after)):
        integrated = set(run.scene.elements[e].law.ode_states)
        names = [name for name in sorted(continuous(new.internal)) if name not in integrated]
        if old != new and names and not carry_numbers(run, e, names, new, lambda scene, c, i, e=e:
                                                       mapped(scene, c, i)[0][e]):
            return f"{run.scene.elements[e].path} passes through the ground's jump onto another branch within the " \
                "parameter's step"
    return rows


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
