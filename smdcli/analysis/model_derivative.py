"""A linear model's derivative with respect to scenario parameters, and the augmented model whose exact solution
carries the response's sensitivities beside the response.

Differentiating M x'' + C x' + K x = B u(t) with respect to a parameter p gives the same structure driven by a
pseudo-load: M s'' + C s' + K s = B du/dp - dM/dp x'' - dC/dp x' - dK/dp x, s = dx/dp, s(0) = dx0/dp. Stacked
with the scene, [x; s_1; ...; s_P] is one linear system with block lower-triangular M, C and K (the scene on
the diagonal, the parameters' derivatives below it) and the scene's own signals with their derivatives as
forces, so the exact solver (the matrix exponential, Van Loan's block form of the sensitivities) solves both.

The model's derivatives (of M, C, K, x0, v0, the ground's jumps and every force's generator) are taken on the
assembled model, never on a solution: the scenario is built at p + o delta for a stencil of offsets o and the
weights that are exact for polynomials of degree 4 combine them. M, C, K, the initial state and a generator's
matrices are polynomials of low degree in every parameter a scenario holds (a stiffness, a mass, a Rayleigh
coefficient, an amplitude, a frequency), so their derivatives are exact to rounding; the rest (modal damping, a
generator's state at a late time) carries the stencil's error, which the same stencil at twice the offsets
estimates and the result states.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import re
from dataclasses import dataclass

import numpy as np

from smdcli import scenario as scenario_mod
from smdcli.analysis.law_keys import law_key, law_moved
from smdcli.analysis.signal_derivative import anchors, combined, signal_derivative
from smdcli.analysis.step_scale import block_scales, relative_size, wider_scale
from smdcli.errors import ScenarioError, UsageError
from smdcli.model import Model, build
from smdcli.model.damping import modal_damping_derivative
from smdcli.model.moved import moved, scaled_ground
from smdcli.model.system import GROUND_DOF
from smdcli.scenario import Scenario
from smdcli.shapes.table import Table
from smdcli.sweep.family import STRUCTURAL, decoded, is_given, parameter_value, set_parameter

CENTRAL = (-2.0, -1.0, 1.0, 2.0)  # offsets in units of delta: exact for polynomials of degree 4 (its symmetry)
FORWARD = (0.0, 1.0, 2.0, 3.0, 4.0)  # where p - delta is not a valid scene (a damper at c = 0): degree 4 too
BACKWARD = (0.0, -1.0, -2.0, -3.0, -4.0)  # where p + delta is not (a kinetic friction force just below its static one)
# relative deltas tried, largest first, until the stencil's error is rounding's: the smallest for a generator's state
# at a late time (a force's frequency over a long run, whose stencil error grows as (delta t)^4), each rounded to a
# power of two, so that p + o delta is p's own number plus an exact one and an array affine in p differs exactly
STEPS = (1e-3, 1e-4, 2e-5, 4e-6, 8e-7, 1.6e-7)
_LINEAR_ELEMENT = re.compile(r"spring\[\d+\]\.k|damper\[\d+\]\.c")
AFFINE_STEP = 1e-2  # relative step of an affine parameter's one difference: exact for any step; larger, less rounding
EPS = np.finfo(float).eps
ROUNDING = 16  # units of rounding in a model's number (a generator's state at a late time: sin(w t) of a large w t)
_REFUSED = ("time.", "solver.", "sweep.", "output.", "plot")  # the run's span and settings: not the scene's


@functools.lru_cache(maxsize=32)
def stencil_weights(offsets: tuple[float, ...]) -> np.ndarray:
    """Weights w with sum w_k f(o_k) = f'(0) exactly for polynomials of degree len(offsets) - 1 (delta = 1); read
    only (a handful of stencils, each solved once)."""
    o = np.asarray(offsets, dtype=float)
    powers = o[None, :] ** np.arange(len(o))[:, None]
    target = np.zeros(len(o))
    target[1] = 1.0
    weights = np.linalg.solve(powers, target)
    weights.flags.writeable = False
    return weights


@dataclass
class Derivative:
    """One parameter's derivative of the assembled model: its models at the stencil's points and the weights
    (already divided by delta) that combine them, and the stencil's estimated relative error."""

    path: str
    value: float
    delta: float
    models: list[Model]
    weights: np.ndarray
    error: float
    offsets: tuple[float, ...] = ()  # each model's offset from the value, in units of delta
    scale: float = 0.0  # what its steps were scaled by (a sensitivity block holds scale dx/dp): |p| where 0
    built_from: tuple = ()  # (scenario, document, base, grid, structure, flowed): finer_stencil.finer's

    def of(self, read) -> np.ndarray:
        """d/dp of a model's array read(model), combined over the stencil (as differences from its first point: the
        weights sum to zero only up to rounding, and an array p does not change must come out exactly zero)."""
        return combined(self.weights, [np.asarray(read(m), dtype=float) for m in self.models])


def _scene_at(sc: Scenario, doc: dict, base: Model, path: str, value: float) -> Model:
    """The scene's model with the parameter at value: the base's moved where it can be, else built again."""
    shortcut = moved(base, sc, path, value)
    if shortcut is None and path == "ground_motion.scale":  # a record's scene rebuilt reads its file again
        shortcut = scaled_ground(base, doc["ground_motion"], parameter_value(doc, path, sc), value)
    if shortcut is None:
        shortcut = law_moved(sc, doc, base, path, value)
    if shortcut is not None:
        return shortcut
    member = copy.deepcopy(doc)
    set_parameter(member, path, value)
    return build(scenario_mod.parse_document(member, sc.text, sc.path))  # the text only names the scenario's source


def _model_arrays(model: Model, t_end: float, flowed: bool = False) -> list[np.ndarray]:
    """Every array of a model a derivative is taken of: matrices, initial state, jumps, generators (with their state
    at the run's end, where a frequency's stencil is least accurate; flowed: at the anchor the exact solver's
    ParameterDerivative flows it from), laws."""
    dense = model.dense()
    arrays = [dense.M, dense.C, dense.K, model.x0, model.v0]
    arrays += [np.concatenate([dx, dv]) for _, dx, dv in model.jumps]
    for signal in model.signals:
        exo = signal.exo()
        if isinstance(signal, Table):
            arrays.append(signal.v)
        elif exo is not None:
            arrays += [exo.S, exo.g, signal.exo_state(anchors(signal, np.array([t_end]))[0] if flowed else t_end)]
        else:
            arrays.append(np.atleast_1d(signal.value(np.array([t_end]))))
    # each law's numbers, a key each: no array above moves with a law's key, and a step scaled to them was widened
    # to 1e-3 absolute, twice a regularization of 1e-3 m/s (dx/dr 14 % off, stated exact)
    arrays += [np.atleast_1d(v) for e in model.nonsmooth for v in (getattr(e.law, k) for k in type(e.law).keys)
               if v is not None]
    return [np.asarray(a, dtype=float) for a in arrays]


def _structure(model: Model, grid: np.ndarray) -> tuple:
    """What must not change with a parameter for its derivative to be a new model's numbers: the DOFs, the
    forces' kinds and discontinuities, the jumps' times, the generators' sizes."""
    t0, t1 = float(grid[0]), float(grid[-1])
    sizes = tuple(None if s.exo() is None else s.exo().S.shape for s in model.signals)
    # times as their bytes: a record's thousands of samples compared at once, not as a tuple of floats each
    tables = tuple(np.asarray(s.t, dtype=float).tobytes() if isinstance(s, Table) else b"" for s in model.signals)
    edges = np.asarray(model.breakpoints(t0, t1), dtype=float).tobytes()
    return (model.dofs, tuple(type(s).__name__ for s in model.signals), model.force_dofs,
            edges, tuple(t for t, _, _ in model.jumps), sizes, tables, model.is_linear)


def derivative(sc: Scenario, doc: dict, base: Model, grid: np.ndarray, path: str,
               base_arrays: list[np.ndarray] | None = None, structure: tuple | None = None,
               flowed: bool = False) -> Derivative:
    """The model's derivative with respect to one parameter path (base_arrays: _model_arrays of base at the grid's
    end, structure: _structure of base, where the caller has them; flowed: the exact solver's, whose generators'
    derivatives flow from their anchors); UsageError where the path is not a number of the scene, or moves what has
    no derivative (a force's discontinuity in time, the model's structure)."""
    if path.startswith(_REFUSED) or path == "zeta":
        raise UsageError(f"--param {path}: not a parameter of the scene (the run's span, its solver and its "
                         "sweep are not differentiated; for zeta give the damper's c)")
    value = parameter_value(doc, path, sc)
    element, key = law_key(base, path)  # a law's key may move its force on a finer scale than its own size
    turns = (element and element.law.key_scale(key)) or math.inf
    scale = min(relative_size(value), turns)
    structure = _structure(base, grid) if structure is None else structure
    t_end = float(grid[-1])
    # the model held: its id stays its own
    arrays = {id(base): (base, base_arrays or _model_arrays(base, t_end, flowed))}

    def arrays_of(model: Model) -> list[np.ndarray]:
        if id(model) not in arrays:
            arrays[id(model)] = (model, _model_arrays(model, t_end, flowed))
        return arrays[id(model)][1]

    if affine(sc, base, path) or flowed and _harmonic_frequency(sc, path):
        return _affine_derivative(sc, doc, base, grid, path, value, scale, structure, arrays_of)
    if sc.damping is not None and sc.damping.modal:
        found = _modal_derivative(sc, doc, base, grid, path, value, scale, structure, arrays_of)
        if found is not None:
            return found
    # never wider than the law's own scale: a belt of 0.2 m/s under r = 1e-5 m/s, widened to 0.2 for the belt's
    # digits, stepped across the whole tanh (dx/d belt 15 times the complex step's, stated 1e-7)
    scale, _ = _step_scale(sc, doc, base, grid, path, value, scale, structure, arrays_of, turns)
    best = refused = None
    for relative in STEPS:
        delta = 2.0 ** round(math.log2(relative * scale))
        for offsets in (CENTRAL, FORWARD, BACKWARD):
            doubled = offsets + tuple(2 * o for o in offsets if 2 * o not in offsets)
            try:
                models = {o: base if o == 0 else _scene_at(sc, doc, base, path, value + o * delta) for o in doubled}
            except ScenarioError as exc:
                refused = exc
                continue  # p - delta or p + delta is not a scene: a one-sided stencil
            break
        else:
            continue  # no stencil of this step fits between the scene's limits: a smaller one may
        for m in models.values():
            _same_structure(m, base, structure, grid, path)
        weights = stencil_weights(offsets) / delta
        wide = stencil_weights(tuple(2 * o for o in offsets)) / delta
        near = [combined(weights, parts) for parts in zip(*(arrays_of(models[o]) for o in offsets))]
        far = [combined(wide, parts) for parts in zip(*(arrays_of(models[2 * o]) for o in offsets))]
        largest = max((float(np.abs(a).max(initial=0.0)) for a in near), default=0.0)
        if largest == 0:
            error, rounding = 0.0, 0.0
        else:
            # R(2 delta) - R(delta) is 15 times the error of R(delta) (both O(delta^4)); rounding: eps |f| sum |w| of
            # each array that changes with p (one that does not is the same number at every point: no rounding)
            error = max(float(np.abs(a - b).max(initial=0.0)) for a, b in zip(near, far)) / 15 / largest
            rounding = _rounding([arrays_of(models[o]) for o in doubled], weights, largest)
        found = Derivative(path, value, delta, [models[o] for o in offsets], weights, error + rounding, offsets, scale)
        if best is None or found.error < best.error:
            best = found
        if error <= rounding:
            break
    if best is None:
        raise _unbuildable(doc, path, value, 8 * STEPS[-1] * scale, refused)
    return best


def _unbuildable(doc: dict, path: str, value: float, step: float, refused: ScenarioError) -> ScenarioError:
    """Why no scene near the parameter could be built: the reader's own line, at the values tried; where the reader
    refused the parameter's own field, the field's: a key the scenario does not write (a misspelt one, named with the
    one it likely means) is not a parameter, and one that takes no other value (a count) has no derivative."""
    if refused.field == path and not is_given(doc, path):
        return ScenarioError(refused.file, refused.field, refused.message)
    if refused.field == path:
        expected = refused.message.split(", found")[0]
        return ScenarioError(refused.file, refused.field, f"{expected}: it takes no value within {step:.3g} of "
                             f"{value:g}, so --param {path} has no derivative")
    return ScenarioError(refused.file, refused.field, f"{refused.message} (with --param {path} at {value:g} +- "
                         f"{step:.3g}: no derivative can be taken there)")


def _same_structure(model: Model, base: Model, structure: tuple, grid: np.ndarray, path: str) -> None:
    """UsageError where the model at a stencil point is not the base's structure with other numbers."""
    if all(getattr(model, name) is getattr(base, name) for name in ("dofs", "signals", "force_dofs", "ground",
                                                                       "cubic", "quadratic")) and \
            [e.path for e in model.nonsmooth] == [e.path for e in base.nonsmooth]:
        return  # the base moved (model/moved.py, or a law's key): its numbers alone changed
    if _structure(model, grid) != structure:
        raise UsageError(f"--param {path}: changes the scene's structure, not only its numbers (a force's "
                         "discontinuity moves in time, or the model changes its form): its derivative is not "
                         "a response sensitivity smd can give")


def _rounding(arrays: list[list[np.ndarray]], weights: np.ndarray, largest: float) -> float:
    """The stencil's rounding relative to the largest derivative, from each model's _model_arrays: eps |f| sum |w| of
    each array that changes with p (one that does not is the same number at every point: no rounding)."""
    values = list(zip(*arrays))
    changed = [max(float(np.abs(v).max(initial=0.0)) for v in parts) for parts in values
               if any(not np.array_equal(parts[0], v) for v in parts[1:])]
    return ROUNDING * EPS * max(changed, default=0.0) * float(np.abs(weights).sum()) / largest


def affine(sc: Scenario, base: Model, path: str) -> bool:
    """Whether every number of the model is affine in the parameter: a mass, stiffness, damper, [system] entry,
    initial state, Rayleigh coefficient, force amplitude, record scale or a smooth law's affine key (not with modal
    damping, whose C follows the modes, nor a mass where the ground jumps, whose jump holds M^-1 C)."""
    owner, _, key = path.rpartition(".")
    if any(e.law.piecewise_linear for e in base.nonsmooth):
        # a law's own numbers multiply internal variables that move with them (k d_p): not affine; a linear spring's
        # k or damper's c enters every mode as M^-1 times it, beside the laws' (the stencil's derivative to 1e-12),
        # where every law's events set internal variables affine in the state (a Clough spring's reloading slope, a
        # quotient, took a one-sided difference's error: 2.6e-4 of dx/dc)
        return bool(_LINEAR_ELEMENT.fullmatch(path)) and not (sc.damping is not None and sc.damping.modal) and \
            any(e.name == owner and e.law == "linear" for e in base.elements) and \
            all(e.law.affine_events for e in base.nonsmooth)
    if any(e.path == owner and key in e.law.affine_keys for e in base.nonsmooth):
        return True
    if STRUCTURAL.match(path):
        # a mass beside a contact that events may hold (Stribeck friction): the held rows' constraint force holds
        # M^-1, and the accelerations the stencil combines are not affine in it (a 1 % difference: 1e-2 off)
        return not (sc.damping is not None and sc.damping.modal) and not (base.jumps and ".m" in path) and \
            not (".m" in path and _changes_mode(base))
    return bool(re.fullmatch(r"damping\.(alpha|beta)|force\[\d+\]\.amplitude|ground_motion\.scale", path))


def _changes_mode(base: Model) -> bool:
    """Whether a smooth scene's laws change mode at events (smooth_refusal: a mix of events and smooth terms)."""
    from smdcli.analysis.smooth_sensitivity import smooth_refusal

    return smooth_refusal(base) is not None


def _harmonic_frequency(sc: Scenario, path: str) -> bool:
    """Whether path is a sine's or cosine's frequency (omega or frequency): its generator's matrix is linear in it
    and its state at the phase's origin does not move, so that the flowed model (ParameterDerivative's) is affine."""
    found = re.fullmatch(r"force\[(\d+)\]\.(omega|frequency)", path)
    return found is not None and int(found[1]) < len(sc.forces) and sc.forces[int(found[1])].type in ("sine", "cosine")


def _affine_derivative(sc: Scenario, doc: dict, base: Model, grid: np.ndarray, path: str, value: float,
                       scale: float, structure: tuple, arrays_of) -> Derivative:
    """An affine parameter's derivative: one difference over a step of AFFINE_STEP of _step_scale's scale, exact up
    to rounding."""
    scale, moved = _step_scale(sc, doc, base, grid, path, value, scale, structure, arrays_of)
    other, delta = moved or _moved_once(sc, doc, base, grid, path, value, scale, structure)  # None: says why
    return dataclasses.replace(_difference(path, value, delta, base, other, arrays_of), scale=scale)


def _step_scale(sc: Scenario, doc: dict, base: Model, grid: np.ndarray, path: str, value: float, scale: float,
                structure: tuple, arrays_of, ceiling: float = math.inf) -> tuple[float, tuple | None]:
    """The scale a parameter's steps are taken in, and (the scene a step of AFFINE_STEP of it away, the step): |p|,
    or step_scale.wider_scale's (at most ceiling) where such a step moves the model by too little and one that wide
    is a scene; (|p|, None) where no scene is a step away (the stencil finds its own side)."""
    try:
        moved = _moved_once(sc, doc, base, grid, path, value, scale, structure)
    except ScenarioError:
        return scale, None
    wider = min(wider_scale(arrays_of(base), arrays_of(moved[0]), moved[1]), ceiling)
    try:
        return (wider, _moved_once(sc, doc, base, grid, path, value, wider, structure)) if wider > scale else \
            (scale, moved)
    except ScenarioError:
        return scale, moved


def _moved_once(sc: Scenario, doc: dict, base: Model, grid: np.ndarray, path: str, value: float, scale: float,
                structure: tuple) -> tuple[Model, float]:
    """The scene at p + AFFINE_STEP of p (or p - it, where p + it is no scene) and the step."""
    for sign in (1.0, -1.0):
        delta = sign * AFFINE_STEP * scale
        try:
            other = _scene_at(sc, doc, base, path, value + delta)
        except ScenarioError as exc:
            refused = exc
            continue
        break
    else:
        raise _unbuildable(doc, path, value, AFFINE_STEP * scale, refused)
    _same_structure(other, base, structure, grid, path)
    return other, delta


def _difference(path: str, value: float, delta: float, base: Model, other: Model, arrays_of,
                error: float = 0.0) -> Derivative:
    """The derivative as the difference of two models a step apart whose numbers are affine in p, its error their
    rounding's (or `error`, where larger)."""
    weights = np.array([-1.0, 1.0]) / delta
    moves = [(float(np.abs(b - a).max(initial=0.0)), a, b) for a, b in zip(arrays_of(base), arrays_of(other))
             if a is not b]  # a moved model keeps what it did not move
    largest = max((move for move, _, _ in moves), default=0.0) / abs(delta)
    if largest > 0:
        error = max(error, _rounding([[a for _, a, _ in moves], [b for _, _, b in moves]], weights, largest))
    return Derivative(path, value, delta, [base, other], weights, error, (0.0, 1.0))


def _modal_derivative(sc: Scenario, doc: dict, base: Model, grid: np.ndarray, path: str, value: float,
                      scale: float, structure: tuple, arrays_of) -> Derivative | None:
    """A mass's, stiffness's or damper's derivative under modal damping, exact: M, K and the elements' C are affine
    in it, and modal damping's C moves with the modes by damping.modal_damping_derivative; the scene a step away
    with that C on its tangent, so that the difference is the derivative (six scenes of a stencil, each with its
    eigenproblem, and their 1e-11, otherwise). None where that has no derivative (damping.py says when)."""
    if not (base.is_linear and not base.jumps and isinstance(base.M, np.ndarray) and STRUCTURAL.match(path)):
        return None
    other, delta = _moved_once(sc, doc, base, grid, path, value, scale, structure)
    if other.added_damping is None or other.jumps:
        return None
    found = modal_damping_derivative(sc, base.M, base.K, (other.M - base.M) / delta, (other.K - base.K) / delta)
    if found is None:
        return None
    slope, rounding = found
    added = base.added_damping + delta * slope
    tangent = other.with_matrices(C=other.C - other.added_damping + added, added_damping=added)
    return _difference(path, value, delta, base, tangent, arrays_of, rounding)


def augmented_model(base: Model, derivatives: list[Derivative]) -> tuple[Model, np.ndarray]:
    """The scene and its P sensitivity systems as one linear model of (P + 1) n DOFs, block i + 1 holding
    scale_i dx/dp_i (scale_i = |p_i|, or 1 at p_i = 0, so that every block is a displacement), and the scales."""
    base = base.dense()
    n, P = base.n, len(derivatives)
    size = (P + 1) * n
    scales = block_scales(derivatives)
    M, C, K = (np.zeros((size, size)) for _ in range(3))
    x0, v0 = np.zeros(size), np.zeros(size)
    for block in range(P + 1):
        rows = slice(block * n, (block + 1) * n)
        M[rows, rows], C[rows, rows], K[rows, rows] = base.M, base.C, base.K
    x0[:n], v0[:n] = base.x0, base.v0
    for i, (d, scale) in enumerate(zip(derivatives, scales)):
        rows = slice((i + 1) * n, (i + 2) * n)
        for target, name in ((M, "M"), (C, "C"), (K, "K")):
            target[rows, :n] = scale * d.of(lambda m, name=name: getattr(m.dense(), name))
        x0[rows], v0[rows] = scale * d.of(lambda m: m.x0), scale * d.of(lambda m: m.v0)
    signals, columns, grounds = [], [], []
    ones = np.ones(n)
    for j, signal in enumerate(base.signals):
        column, ground = np.zeros(size), np.zeros(size)
        if base.force_dofs[j] == GROUND_DOF:
            ground[:n] = 1.0
            column[:n] = -base.M @ ones
            for i, (d, scale) in enumerate(zip(derivatives, scales)):
                column[(i + 1) * n:(i + 2) * n] = -scale * d.of(lambda m: m.dense().M) @ ones
        else:
            column[base.force_dofs[j]] = 1.0
        signals.append(signal)
        columns.append(column)
        grounds.append(ground)
        own = column, ground
        for i, (d, scale) in enumerate(zip(derivatives, scales)):
            derived = signal_derivative(signal, d, j)
            if derived is None:
                continue
            if isinstance(derived, float):  # du/dp = derived u: the signal itself acts on the block too
                (column, ground), by = own, scale * derived
            else:
                column, ground, by = np.zeros(size), np.zeros(size), scale
                signals.append(derived)
                columns.append(column)
                grounds.append(ground)
            on = slice((i + 1) * n, (i + 2) * n)
            if base.force_dofs[j] == GROUND_DOF:
                column[on] += -by * (base.M @ ones)
                ground[on] += by
            else:
                column[(i + 1) * n + base.force_dofs[j]] += by
    jumps = []
    for k, (t, dx, dv) in enumerate(base.jumps):
        jx, jv = np.zeros(size), np.zeros(size)
        jx[:n], jv[:n] = dx, dv
        for i, (d, scale) in enumerate(zip(derivatives, scales)):
            jx[(i + 1) * n:(i + 2) * n] = scale * d.of(lambda m: m.jumps[k][1])
            jv[(i + 1) * n:(i + 2) * n] = scale * d.of(lambda m: m.jumps[k][2])
        jumps.append((t, jx, jv))
    names = tuple(base.dofs) + tuple(f"d{dof}/d{d.path}" for d in derivatives for dof in base.dofs)
    model = dataclasses.replace(
        base, dofs=names, M=M, C=C, K=K, x0=x0, v0=v0, signals=tuple(signals),
        force_dofs=tuple(0 for _ in signals), force_paths=tuple(f"input[{j}]" for j in range(len(signals))),
        force_types=tuple(type(s).__name__ for s in signals), cubic=None, quadratic=None, element_form=False,
        ground=None, jumps=tuple(jumps), elements=(), added_damping=None, nonsmooth=(),
        # given, not derived: a column may act on several blocks (the ground's -M 1 and its derivative -dM 1), which
        # force_dofs cannot say; and what each input adds to the blocks' absolute accelerations (the ground's a_g and
        # its derivative on every DOF)
        inputs=np.array(columns).T.reshape(size, len(columns)),
        ground_inputs=np.array(grounds).T.reshape(size, len(grounds)))
    return model, scales


def check_once(paths: list[str]) -> None:
    """UsageError naming a parameter path given more than once."""
    repeated = sorted({p for p in paths if paths.count(p) > 1})
    if repeated:
        raise UsageError(f"--param {repeated[0]}: given more than once")


def model_derivatives(sc: Scenario, base: Model, grid: np.ndarray, paths: list[str],
                      doc: dict | None = None, flowed: bool = False) -> list[Derivative]:
    """Each parameter's model derivative (paths as the sweep takes them; doc: the scenario's TOML document where the
    caller has it; flowed: for the exact solver's augmented model); UsageError for a path given twice."""
    check_once(paths)
    doc = decoded(sc.text) if doc is None else doc  # decoded once per text; _scene_at copies before it edits
    base_arrays, structure = _model_arrays(base, float(grid[-1]), flowed), _structure(base, grid)
    return [dataclasses.replace(derivative(sc, doc, base, grid, path, base_arrays, structure, flowed),
                                built_from=(sc, doc, base, grid, structure, flowed)) for path in paths]
