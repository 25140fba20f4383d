"""Sensitivities of piecewise-linear scenes (elastoplastic and bilinear springs, Coulomb friction, stops), exact
event to event.

Between two events the scene is z' = A z + b (solvers.events.scene), so its sensitivity s = dz/dp obeys
s' = A s + dA/dp z + db/dp: stacked with z, one linear system whose exact flow (the block-triangular exponential)
carries s beside the state, the mode's derivatives taken on the assembled scene (the stencil of
model_derivative, never on a solution). An event of p-dependent time t*, where a guard h = row z + c crosses zero,
moves with the parameter: dt*/dp = -(row s + dh/dp) / (row z'), and the state's sensitivity jumps across it
(the saltation): s+ = D[Delta](s- + z'- dt*/dp) - z'+ dt*/dp, with Delta the event's map of the state (the
identity for a change of mode, the velocity jump of an impact) and D its derivative along the moved event point.
The elements' internal variables (a spring's plastic deformation, set where it unloads) carry sensitivities of
their own, set the same way from the law's own event at the moved point; the mode after an event reads them.

Where a derivative does not exist (an event met tangentially, a graze: its time's derivative is infinite; an
accumulation of impacts), the sensitivities from that time on are not numbers: they are nan, and the result says
from when and why.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.elements.base import KINK, RATE
from smdcli.elements import State
from smdcli.analysis.event_carry import CarriedSensitivities
from smdcli.analysis.event_edges import (GRAZE, breakaway_margins, carry_numbers, continuous, internal_values,
                                           shifted_states, start_derivative)
from smdcli.analysis.finer_stencil import FINER, finer
from smdcli.analysis.signal_derivative import stencil_total
from smdcli.analysis.smooth_sensitivity import ANSWERED
from smdcli.model import Model
from smdcli.solvers.events.decisions import impact, project
from smdcli.solvers.events.piecewise import PiecewiseRun
from smdcli.solvers.events.scene import Scene
from smdcli.solvers.exact.flow import Flow
from smdcli.solvers.exact.hold import first_order_hold, held_paths, hold_error, subdivided

GRAZING = 1e-9  # a crossing whose rate is below this share of the terms it sums is met tangentially: no dt*/dp
# what the sensitivities are stated to, relative to each parameter's largest: the rounding of each event's time
# divided by its crossing rate is not bounded a priori; differences of the exact runs agree to 6e-11 - 3e-10 (their
# own error) on yielding, stick-slip, impacts and a bilinear frame
EVENT_ERROR = 1e-9
# the laws whose events carry their sensitivities
SUPPORTED = ("elastoplastic", "bilinear", "clough", "iwan", "coulomb", "stop")


def event_refusal(model: Model) -> str | None:
    """Why the event-to-event sensitivities cannot take the scene, or None."""
    for element in model.nonsmooth:
        law = element.law
        if not law.piecewise_linear or law.name not in SUPPORTED:
            return (f"{element.path} ({getattr(law, 'law_name', law.name)}): sensitivities of this law are not yet "
                    f"built (built: {ANSWERED})")
    if model.cubic is not None or model.quadratic is not None:
        return ("cubic springs or quadratic dampers beside yielding, friction or stops: sensitivities of such a mix are "
                "not yet built")
    return None


class EventSensitivityRun(PiecewiseRun, CarriedSensitivities):
    """The exact event-driven run with the P scaled sensitivities scale_i dz/dp_i carried beside the state."""

    def __init__(self, model: Model, grid: np.ndarray, derivatives: list, scales: np.ndarray):
        super().__init__(model, grid)
        self.P = len(derivatives)
        # each parameter's stencil: the scenes at its points, their offsets (in the parameter's units) and weights
        # (times its scale: the sensitivities carried are scale_i d/dp_i, every block the size of the state)
        self.stencils = [self._stencil(d, scale, grid) for d, scale in zip(derivatives, scales)]
        self.derivatives = derivatives
        self.scales = scales
        self.dq = [{} for _ in self.scene.elements]  # internal variable -> its (P,) scaled sensitivities
        self.h_out = float(grid[1] - grid[0]) if len(grid) > 1 else 0.0
        self.checkpoints: list[tuple] = []  # (t, z, S, states, dq) at the start, each event and each break
        self.moves: dict[float, np.ndarray] = {}  # each event's time -> its scaled derivatives scale_i dt*/dp_i
        self.undefined_from: tuple[float, str] | None = None
        self.peak_points: list[tuple] = []  # (t, x, scale_i dx/dp_i along the moved event) at each event: peaks there
        # parameters whose own step moves the start across an element's edge (a spring deformed to its yield point
        # exactly, the stiffness moved): they alone have no derivative, from the start; the others do
        self.edges: dict[int, str] = {}
        self.held = ""  # how a force without a generator was held (event_sensitivities), if one was
        self._augmented: dict = {}
        self._flows: dict[bytes, Flow] = {}  # the augmented flows, by their matrix
        self._seeds: dict[float, tuple] = {}  # (sensitivities', state's) generators reseeded at a break, by its time

    # ----------------------------------------------------------------------------- stencils
    @staticmethod
    def _stencil(d, scale: float, grid: np.ndarray) -> tuple:
        """A derivative's stencil as the run reads it: the scenes at its points, their offsets (in the parameter's
        units) and weights (times its scale: the sensitivities carried are scale_i d/dp_i, every block the size of
        the state)."""
        return ([Scene(first_order_hold(m, grid)[0]) for m in d.models], np.asarray(d.offsets, dtype=float) * d.delta,
                d.weights * scale)

    def total(self, i: int, read) -> np.ndarray:
        """scale_i times the total derivative along parameter i of read(scene, c) (stencil_total)."""
        return stencil_total(self.stencils[i], self.scales[i], read)

    def shifted(self, states, i: int, c: float, dq: list | None = None) -> list[State]:
        """The states with their internal variables moved c times their scaled sensitivities to parameter i (dq: as
        a checkpoint kept them; the run's current ones by default)."""
        return shifted_states(states, self.dq if dq is None else dq, i, c)

    def augmented(self, states, dq: list) -> tuple[Flow, np.ndarray, np.ndarray]:
        """The flow of [z; S] in these states with these internal sensitivities, its forcing and its matrix: the mode
        with each parameter's total derivative of A and b below it."""
        mode = self.scene.mode(states)
        key = (mode.key, tuple(tuple(sorted((k, v.tobytes()) for k, v in d.items())) for d in dq))
        found = self._augmented.get(key)
        if found is None:
            s, P = self.scene.size, self.P
            big = np.zeros(((P + 1) * s, (P + 1) * s))
            forcing = np.zeros((P + 1) * s)
            forcing[:s] = mode.b
            for block in range(P + 1):
                big[block * s:(block + 1) * s, block * s:(block + 1) * s] = mode.A
            for i in range(P):
                def read(scene, c, i=i):
                    shifted = scene.mode(self.shifted(states, i, c, dq))
                    return np.concatenate([shifted.A.ravel(), shifted.b])
                flat = self.total(i, read)
                big[(i + 1) * s:(i + 2) * s, :s] = flat[:s * s].reshape(s, s)
                forcing[(i + 1) * s:(i + 2) * s] = flat[s * s:]
            # the flow by its matrix: internal variables move the forcing only (a plastic deformation), so that a
            # mode met again after an event steps on the exponentials it already has
            flow = self._flows.get(matrix := big.tobytes())
            if flow is None:
                flow = self._flows[matrix] = Flow(big)
            found = self._augmented[key] = (flow, forcing, big)
        return found

    def advance(self, t: float, z: np.ndarray) -> None:
        """S carried from the last checkpoint to t (the run's own z at t kept), as a checkpoint."""
        last = self.checkpoints[-1]
        t_c, z_c, S_c, states_c, dq_c = last
        if t > t_c:
            Z = self.carry(np.concatenate([z_c, S_c.ravel()]), t_c, t, last)
            S_c = Z[len(z):].reshape(self.P, len(z))
        self.checkpoints.append((t, z.copy(), S_c, states_c, dq_c))

    def settle_checkpoint(self, t: float, z: np.ndarray, S: np.ndarray, states) -> None:
        """The state after an event or break, with its sensitivities, as the next segment's start."""
        self.checkpoints.append((t, z.copy(), S, list(states), [{k: v.copy() for k, v in d.items()} for d in self.dq]))

    def no_derivative(self, t: float, why: str) -> None:
        """From t on the response has no derivative: nan from here, the reason kept."""
        if self.undefined_from is None:
            self.undefined_from = (t, why)

    # ----------------------------------------------------------------------------- the run's hooks
    def flow(self, mode, t: float) -> Flow:
        self.now = t  # the step's start, for what first_crossing finds
        return super().flow(mode, t)

    def first_crossing(self, flow: Flow, mode, z0: np.ndarray, z1: np.ndarray, h: float):
        found = super().first_crossing(flow, mode, z0, z1, h)
        if self.undefined_from is None:
            end = h if found is None else found[0]
            crossing = None if found is None else found[1:]
            self.near_miss(flow, mode, z0, z1 if found is None else flow.at(z0, mode.b, end), end, crossing)
        return found

    def near_miss(self, flow: Flow, mode, z0: np.ndarray, z1: np.ndarray, h: float, crossing=None) -> None:
        """A guard whose top comes within GRAZE of its level on (0, h] without crossing it: an event that a change
        of the parameters this small makes appear, so that the response has no derivative from there. The guard
        an event crosses at h (crossing: its element and guard) reaches its level there: not a miss."""
        for e, guard, row, const in mode.guards:
            if crossing is not None and (e, guard) == tuple(crossing):
                continue
            direction = guard.direction
            scale = self._graze_scale(guard, row, const, z0)
            if not (direction * float(row @ z0 + const) < -GRAZE * scale and direction * float(row @ z1 + const) < 0):
                continue
            slope0, slope1 = (direction * float(row @ (mode.A @ z + mode.b)) for z in (z0, z1))
            if not slope0 > 0 > slope1:
                continue
            turn, value = self._turn_top(flow, mode, z0, row, const, h)
            top = direction * value
            if top >= -GRAZE * scale:
                self.no_derivative(self.now + turn, f"{self.scene.elements[e].path} comes within {-top:.3g} of its "
                                   f"{guard.kind} without reaching it: a graze, which a change of the parameters that "
                                   "small turns into an event")

    def batch(self, *args, **kwargs):
        """Whole output steps at once where no break falls among them: the sensitivities are carried from event to
        event and read at the output points after the run (outputs). A record's samples are breaks that a batch
        reseeds in stride, and a jump there may settle modes inside it: step by step, each break a checkpoint."""
        before = len(self.events)
        found = super().batch(*args, **kwargs)
        if found is not None and len(self.events) > before:  # a jump at a sample settled modes inside the batch
            states, z, t, _ = found
            self.advance(t, z)
            S = self.checkpoints[-1][2]
            self.carry_internal(args[2], states, z, S, self.events[before:])
            self.settle_checkpoint(t, z, S, states)
        return found

    def kink_slack(self, size: np.ndarray, const: np.ndarray) -> np.ndarray:
        # a guard within GRAZE of its level at a kink: touched_at_break decides on the step path
        return GRAZE * (np.maximum(size, self.v_scale) + np.abs(const))

    def turn_margin(self, guard, row, const, z0) -> float:
        # a near miss inside a batch too: the step-by-step path takes that step, where first_crossing sees it
        return GRAZE * self._graze_scale(guard, row, const, z0)

    def _graze_scale(self, guard, row: np.ndarray, const: float, z0: np.ndarray) -> float:
        """What a guard's nearness to its level is judged against: the terms it sums, or for a rate the run's speeds
        (a contact that has just broken away has no speed of its own to judge by)."""
        size = float(np.abs(row) @ np.abs(z0)) + abs(const)
        return max(size, self.v_scale) if guard.quantity == RATE else size

    def start(self, states, z: np.ndarray, t: float):
        held_margins = breakaway_margins(self.scene, states, z)  # before the start's decisions
        before = len(self.events)
        states, z = super().start(states, z, t)
        if any(kind == "impact" for _, _, kind in self.events[before:]):
            self.no_derivative(t, "a stop is met moving into it at the start")
        E = self.scene.E
        S = np.zeros((self.P, self.scene.size))
        nominal = np.array([v for s in states for v in internal_values(s)])
        for i in range(self.P):
            flat, edge = start_derivative(self.scene, self.stencils[i], self.scales[i], t, states, nominal,
                                          held_margins)
            # its stencil's step crosses an edge: the start is on it only if a step near the parameter's rounding
            # still does (the step's, 1e-3 of a speed wide, kept a fit 2.4e-3 off a truth on the edge)
            for share in FINER if edge else ():
                found = finer(self.derivatives[i], share)
                if found is None:
                    break
                flat, edge = start_derivative(self.scene, self._stencil(found, self.scales[i], self.grid),
                                              self.scales[i], t, states, nominal, held_margins)
                if not edge:
                    self.derivatives[i].error = found.error  # its rounding, in the accuracy the result states
                    break
            if edge:
                # a start on the edge of two branches (deformed to its yield point exactly, held at its breakaway):
                # carried as zeros, read as nan (outputs, state_at, rates_at)
                d = self.derivatives[i]
                reach = abs(d.delta) * max(map(abs, d.offsets)) * min(FINER, default=1.0) / self.scales[i]
                self.edges[i] = (f"{', '.join(edge)} starts on the edge between two of its branches (within "
                                 f"{reach:.1g} of the parameter, relative: a spring deformed to its yield point, a "
                                 "contact held at its breakaway force), where the response's derivatives on either "
                                 "side differ")
                flat = np.zeros_like(flat)
            S[i] = flat[:self.scene.size]
            at = self.scene.size
            for e in range(E):
                for name in sorted(continuous(states[e].internal)):
                    self.dq[e].setdefault(name, np.zeros(self.P))[i] = flat[at]
                    at += 1
        self.settle_checkpoint(t, z, S, states)
        return states, z

    def apply(self, states, z: np.ndarray, t: float, element: int, kind: str):
        if kind == KINK or self.undefined_from is not None:
            self.peak_points.append((t, z[:self.n].copy(), np.full((self.P, self.n), np.nan)))
            return super().apply(states, z, t, element, kind)
        self.advance(t, z)
        S = self.checkpoints[-1][2]
        mode = self.scene.mode(states)
        rate_of_z = mode.A @ z + mode.b
        index = min((j for j, (e, guard, _, _) in enumerate(mode.guards) if e == element and guard.kind == kind),
                    key=lambda j: abs(float(mode.guards[j][2] @ z + mode.guards[j][3])))
        row = mode.guards[index][2]
        crossing = float(row @ rate_of_z)
        dt = np.zeros(self.P)
        if abs(crossing) <= GRAZING * float(np.abs(row) @ np.abs(rate_of_z)):
            self.no_derivative(t, f"{self.scene.elements[element].path} meets its {kind} tangentially: a graze, "
                               "whose time has no derivative")
        else:
            for i in range(self.P):
                def guard(scene, c):
                    _, _, r, const = scene.mode(self.shifted(states, i, c)).guards[index]
                    return r @ z + const
                dt[i] = -(float(row @ S[i]) + float(self.total(i, guard))) / crossing
        self.moves.setdefault(t, dt)
        moved = S + dt[:, None] * rate_of_z[None]  # the event point's total derivative
        self.peak_points.append((t, z[:self.n].copy(), moved[:, :self.n].copy()))
        before = len(self.events)
        after, z_after = super().apply(states, z, t, element, kind)
        recorded = self.events[before:]
        if kind == "impact":
            S_after = self.impact_jump(states, after, z, moved, element, recorded, t)
        else:
            S_after = moved.copy()
        self.carry_internal(states, after, z, moved, recorded)
        mode_after = self.scene.mode(after)
        S_after -= dt[:, None] * (mode_after.A @ z_after + mode_after.b)[None]
        self.settle_checkpoint(t, z_after, S_after, after)
        return after, z_after

    def impact_jump(self, before, after, z, moved, element, recorded, t) -> np.ndarray:
        """D[Delta] of an impact along the moved event point: the velocity jump (and a rest's projection) of the
        scene at each stencil point."""
        kinds = [kind for _, path, kind in recorded if path == self.scene.elements[element].path]
        if "impact" not in kinds:
            self.no_derivative(t, f"{self.scene.elements[element].path} is touched, not struck (a graze)")
            return moved.copy()
        if any(kind == "rest" and when != t for when, _, kind in recorded):
            self.no_derivative(t, f"{self.scene.elements[element].path}'s impacts accumulate to rest")
            return moved.copy()
        out = np.empty_like(moved)
        for i in range(self.P):
            def jumped(scene, c, i=i):
                law = scene.elements[element].law
                struck = impact(scene, self.shifted(before, i, c), z + c * moved[i], element, law.rebound)
                return project(scene, self.shifted(after, i, c), struck, self.v_scale)
            out[i] = self.total(i, jumped)
        return out

    def carry_internal(self, before, after, z, moved, recorded) -> None:
        """The internal variables' sensitivities an event sets: the law's own event at the moved point."""
        for e, (old, new) in enumerate(zip(before, after)):
            if old.internal == new.internal:
                continue
            path = self.scene.elements[e].path
            kinds = [kind for _, p, kind in recorded if p == path]
            if len(kinds) != 1:
                self.no_derivative(recorded[0][0] if recorded else 0.0,
                                   f"{path} changes its internal variables by several events at one instant")
                return

            def event(scene, c, i):
                shifted = self.shifted(before, i, c)
                d, rate, tension, _ = scene.evaluate(shifted, z + c * moved[i])
                return scene.elements[e].law.event(shifted[e], kinds[0], float(d[e]), float(rate[e]), float(tension[e]))
            if not carry_numbers(self, e, sorted(continuous(new.internal)), new, event):
                # the event leads elsewhere within the parameter's step (a line's target)
                self.no_derivative(recorded[0][0], f"{path}'s {kinds[0]} leads to another branch within the "
                                   "parameter's step: its derivatives on either side differ")
                return

    def cross_break(self, states, z: np.ndarray, t: float, jump):
        self.advance(t, z)
        self.touched_at_break(states, z, t)
        S = self.checkpoints[-1][2]
        before = len(self.events)
        after, z_after = super().cross_break(states, z, t, jump)
        S = self._reseeded(np.concatenate([z, S.ravel()]), t)[self.scene.size:].reshape(S.shape)
        if jump is not None:  # the ground's: the state jumps
            S = self.across_jump(states, after, z, S, t)
        else:
            self.carry_internal(states, after, z, S, self.events[before:])
        self.settle_checkpoint(t, z_after, S, after)
        return after, z_after


    def touched_at_break(self, states, z: np.ndarray, t: float) -> None:
        """A guard that reaches its level just where the force has a kink or a jump (a contact's force touching its
        breakaway as the force turns back): on one side of the parameter's step an event there, on the other none or
        one at another crossing rate, so that the response has no derivative from t."""
        if self.undefined_from is not None:
            return
        mode = self.scene.mode(states)
        rate_of_z = mode.A @ z + mode.b  # the left limits: the generators not reseeded yet
        for e, guard, row, const in mode.guards:
            value = guard.direction * float(row @ z + const)
            slope = guard.direction * float(row @ rate_of_z)
            if abs(value) <= GRAZE * self._graze_scale(guard, row, const, z) and \
                    slope > GRAZING * float(np.abs(row) @ np.abs(rate_of_z)):
                self.no_derivative(t, f"{self.scene.elements[e].path} reaches its {guard.kind} at t = {t:.6g} s, "
                                   "just where the force turns or jumps: its derivatives on either side differ")
                return


HOLD_TARGET = 1e-10  # a held force's gap between samples, of its peak, that needs no finer samples
FINEST_HOLD = 64  # samples of a held force an output step, at most
HELD_ROWS = 2**20  # rows of the finely held run, at most


def event_sensitivities(model: Model, derivatives: list, scales: np.ndarray, grid: np.ndarray):
    """(x, v, a (N, n), S (N, P, 2n) scaled sensitivities of x and v, dA (N, P, n) of a, the run, the state's stated
    accuracy (the sensitivities': EVENT_ERROR at least)) of a piecewise-linear scene by the exact event-driven run.
    A force without a generator (a chirp, a formula) is held linearly between samples a power of two to an output
    step (the fewest whose gap is within HOLD_TARGET of its peak, at most FINEST_HOLD), and the run is taken again
    at half as many: the hold's error, O(step^2), is a third of the two runs' difference, and twice that is stated;
    the two are combined by Richardson's rule, which cancels it (held on the output grid alone, a stop scene under a
    decaying sine was 1.7e-2 off, stated 1e-9)."""
    held = held_paths(model)
    per_step = _held_samples(model, grid, held) if held and len(grid) > 1 else 1
    x, v, a, S, d_a, run = _sampled_run(model, derivatives, scales, grid, per_step)
    stated = run.stated(len(run.events))
    if per_step > 1:
        n = model.n
        xc, vc, ac, Sc, d_ac, run.coarse = _sampled_run(model, derivatives, scales, grid, per_step // 2)
        gap = max(_gap((x, S[:, :, :n]), (xc, Sc[:, :, :n])), _gap((v, S[:, :, n:]), (vc, Sc[:, :, n:])),
                  _gap((a, d_a), (ac, d_ac)))
        stated = max(stated, 2.0 / 3.0 * gap)
        # the hold's O(step^2) error cancels in Richardson's combination (a stop scene under a decaying sine: the
        # sensitivities 4.0e-6 -> 8.5e-8 off, the state 6.0e-7 -> 9.3e-11); the fine run's own error is stated
        x, v, a, S, d_a = ((4.0 * fine - coarse) / 3.0 for fine, coarse in ((x, xc), (v, vc), (a, ac), (S, Sc),
                                                                            (d_a, d_ac)))
        run.held = (f"{', '.join(held)} held linearly between {per_step} samples an output step (error "
                    f"{2.0 / 3.0 * gap:.1e}, from the run at half as many)")
    return x, v, a, S, d_a, run, stated


def _gap(fine: tuple, coarse: tuple) -> float:
    """The largest difference of two runs' (nominal, derived) blocks, relative to the fine run's largest entry (a
    derivative said not to exist, nan, is left out)."""
    peak = max(float(np.abs(fine[0]).max(initial=0.0)), float(np.nanmax(np.abs(fine[1]), initial=0.0)), 1e-300)
    return max(float(np.abs(fine[0] - coarse[0]).max(initial=0.0)),
               float(np.nanmax(np.abs(fine[1] - coarse[1]), initial=0.0))) / peak


def _held_samples(model: Model, grid: np.ndarray, held: tuple[str, ...]) -> int:
    """Samples of the held forces an output step: a power of two from 2, the fewest whose gap is within HOLD_TARGET of
    the force's peak, at most FINEST_HOLD and HELD_ROWS rows."""
    per_step = 2
    while per_step < FINEST_HOLD and 2 * per_step * (len(grid) - 1) <= HELD_ROWS and \
            hold_error(model, subdivided(grid, per_step), held) > HOLD_TARGET:
        per_step *= 2
    return per_step


def _sampled_run(model: Model, derivatives: list, scales: np.ndarray, grid: np.ndarray, per_step: int):
    """The event-driven run with the forces held on the grid sampled per_step times a step, read on the grid:
    (x, v, a, S, dA, the run)."""
    fine = subdivided(grid, per_step)
    run = EventSensitivityRun(first_order_hold(model, fine)[0], fine, derivatives, scales)
    x, v, a, _ = run.run()
    n = model.n
    S, rates = run.outputs()
    run.output_rows = rows = slice(None, None, per_step)
    return x[rows], v[rows], a[rows], S[rows, :, :2 * n], rates[rows, :, n:2 * n], run
