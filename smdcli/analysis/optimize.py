"""Design by optimization: the parameters within bounds that minimize a response measure, with exact gradients.

Objectives (the parameter paths are the sweep's, every one bounded):
- peak_receptance:<dof>: the H-infinity norm, max over all frequencies of |x_dof / F| for a unit force on the
  scenario's first force's DOF (or `input`). Every local maximum of |H| is located on the exact receptance as the zero
  of d|H|^2/dw (Brent's method between the neighbours of a grid laid over the modes), and the minimax is solved as
  such: the epigraph min t subject to t >= |H(w_j)| for each peak j, each with its exact gradient (at a peak
  d|H|/dw = 0, so d|H(w_j)|/dp = Re(conj(H) dH/dp) / |H| at the fixed w_j, dH/dp = -Z^-1 dZ/dp H), by SLSQP.
- rms:<dof>: the RMS displacement under white noise of one-sided PSD 1 N^2/Hz on the input (smd psd's convention;
  1 (m/s^2)^2/Hz on a support that shakes a scene without forces), sqrt(Sigma_dd) of the Lyapunov equation
  A Sigma + Sigma A^T + B B^T / 2 = 0, its gradient from the same equation differentiated (A dSigma + dSigma A^T =
  -(dA Sigma + Sigma dA^T + d(B B^T) / 2)); rms_drift:<a>-<b> and rms_acceleration:<dof> (absolute) the same way;
  under a PSD profile, the integral of |H|^2 S and of its derivative by quadrature.
- peak_displacement:<dof>: the largest |x_dof| of the scenario's own run, located between samples, its gradient the
  exact sensitivity of the located peak (linear, yielding, friction, stop and smooth nonlinear scenes).

The model's derivatives are model_derivative's (the assembled scene at the parameter's stencil points). A local
optimum is not silently the answer: the search starts from the scenario's own values and from a Latin hypercube
in the bounds, and every distinct optimum found is reported.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import math
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.analysis.dissipation import dissipators
from smdcli.analysis.model_derivative import check_once, model_derivatives
from smdcli.analysis.objectives import (PEAKS, RMS, TIME_DOMAIN, TIME_PEAK_KINDS, UNITS, Objective, read_constraint,
                                        read_objective)
from smdcli.analysis.optimize_search import FEASIBLE, local_search, stationary, violation
from smdcli.analysis.response_measures import TIME_PEAKS, receptance_peaks, rms, time_measure, transmissibility_peaks
from smdcli.errors import ScenarioError, UsageError
from smdcli.model import build, time_grid
from smdcli.model.system import GROUND_DOF
from smdcli.scenario import Scenario
from smdcli.sweep.family import corner_span, member_with, parameter_value, scenario_with, structural

DISTINCT = 1e-3  # optima closer than this share of the bounds' widths are one
CORNERS = 6  # the most parameters whose box's 2^P corners are built to interpolate a linear measure's matrices


@dataclass
class Optimum:
    """The result of `smd optimize`."""

    scenario: str
    objective: str
    units: str
    parameter: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    initial: np.ndarray
    optimum: np.ndarray
    value_before: float
    value: float
    gradient: np.ndarray  # at the optimum, per unit of each parameter
    on_bound: np.ndarray  # (P,) -1 lower, +1 upper, 0 inside
    converged: bool
    message: str
    iterations: int
    solves: int
    history_objective: np.ndarray
    history_parameters: np.ndarray
    optima: list[tuple[np.ndarray, float]]  # distinct local optima found, best first
    # located peaks: (frequency rad/s, |H|) rows, or (time s, |x|) of a largest peak in time
    peaks_before: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    peaks: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    wall_time_s: float = 0.0
    outputs: list = field(default_factory=list)
    sc: Scenario | None = None
    input_dof: int | None = 0  # the DOF a unit force acts on; None: the support's acceleration
    constraints: list = field(default_factory=list)  # (text, limit, value at the optimum, binds)
    records: list = field(default_factory=list)  # (record file, the measure under it at the optimum)
    over: str = "max"
    problem: object = None  # the Problem it was found on: the measures at any point (a contour plot's)

    @property
    def in_frequency(self) -> bool:
        """Whether the objective is a frequency response's peak (drawn against frequency, its peaks marked)."""
        return self.objective.partition(":")[0] in PEAKS

    @property
    def peak_axis(self) -> tuple[str, str]:
        """What the first column of peaks is: (name, units)."""
        return ("frequency", "rad/s") if self.in_frequency else ("time", "s")


class Problem:
    """The objective and the constraints' measures, each with its exact gradient, at any parameter values within
    the bounds; a scene solved once per point (its model's derivatives, or its sensitivities, serve every measure)."""

    def __init__(self, sc: Scenario, paths: list[str], objective: Objective, input_dof: int | None,
                 constraints: tuple = (), records: tuple = (), over: str = "max", psd=None):
        self.sc, self.paths, self.objective, self.input_dof = sc, paths, objective, input_dof
        self.psd = psd  # the input's one-sided PSD in SI: a profile, a white level, or None for white noise of 1
        self.constraints = constraints  # (Objective, limit) pairs: measure <= limit
        self.records, self.over = records, over  # (path, the scenario under that record) pairs
        self.solves = 0
        self._cache: dict[bytes, dict] = {}
        self._span = None  # (base, lower, width, coefficients at lower, each parameter's change over its width)

    def interpolate(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Solve the linear measures on matrices interpolated between the box's validated corners (the sweep's
        structural members) rather than on a scene built at every point, where every path enters M, C and K
        affinely: the same numbers to rounding, and the model's derivatives exact and constant."""
        base = build(self.sc).dense()
        kinds = [m.kind for m in (self.objective, *(m for m, _ in self.constraints))]
        if (len(self.paths) > CORNERS or any(k in TIME_DOMAIN for k in kinds) or not base.is_linear
                or "zeta" in self.paths or (self.sc.damping is not None and self.sc.damping.modal)
                or not structural(base, self.paths)):
            return
        try:
            origin, changes = corner_span(self.sc, lambda v: scenario_with(self.sc, dict(zip(self.paths, v))),
                                          lower, upper)
        except ScenarioError:
            return  # a corner is not a scene: each point is built, and judged, on its own
        self._span = (base, lower, upper - lower, origin, changes)

    def _interpolated(self, values: np.ndarray) -> tuple:
        """The dense model at values and each parameter's (dM, dC, dK), from the corners' span."""
        base, lower, width, origin, changes = self._span
        weights = (values - lower) / width
        matrices = {name: origin[name] + sum(w * change[name] for w, change in zip(weights, changes))
                    for name in "MCK"}
        return (base.with_matrices(**matrices),
                [tuple(change[name] / w for name in "MCK") for change, w in zip(changes, width)])

    @property
    def minimax(self) -> bool:
        """Whether the objective is a largest of several smooth pieces, minimized as such (the epigraph): a
        frequency response's peaks, a run's peaks in time, or the worst of several records."""
        kind = self.objective.kind
        return kind in PEAKS or (bool(self.records) or kind in TIME_PEAK_KINDS) and self.over == "max"

    def slots(self, measure: Objective) -> int:
        """How many pieces of a largest the search holds a constraint for: a receptance's peaks (one a mode, and
        the static one), a run's largest peaks in time, one per record or both."""
        each = TIME_PEAKS if measure.kind in TIME_PEAK_KINDS else 1
        if self.records:
            return len(self.records) * each
        return len(self.sc.dof_names) + 1 if measure.kind in PEAKS else each

    def value(self, values: np.ndarray, forward=None) -> float:
        """The objective alone at values, no gradient (what a contour plot draws): a linear measure of the scene
        there; a time-domain one from forward(scene), a solved run (Result), per record where there are records."""
        if self._span is not None:
            return self.evaluate(values)[0]
        scene = self.scene(values)
        if self.objective.kind not in TIME_DOMAIN:
            return Problem(scene, [], self.objective, self.input_dof, psd=self.psd).evaluate(np.zeros(0))[0]
        scenes = [scenario_with(under, dict(zip(self.paths, map(float, values)))) for _, under in self.records]
        each = [time_measure(_as_run(forward(s)), self.objective)[0] for s in scenes or [scene]]
        return float(np.mean(each) if self.over == "mean" else np.max(each))

    def record_values(self, values: np.ndarray) -> list[float]:
        """The objective under each record at values."""
        self.evaluate(values)
        point = self._cache[np.asarray(values, dtype=float).tobytes()]
        return [time_measure(s, self.objective)[0] for s in point["records"]]

    def scene(self, values: np.ndarray) -> Scenario:
        """The scenario at these values (ScenarioError naming what a value makes invalid)."""
        return scenario_with(self.sc, dict(zip(self.paths, map(float, values))))

    def evaluate(self, values: np.ndarray, measure: Objective | None = None) -> tuple:
        """(value, gradient, detail) of a measure (the objective by default) at values: detail a receptance's peaks
        (w, |H|, d|H|/dp rows)."""
        measure = measure or self.objective
        key = np.asarray(values, dtype=float).tobytes()
        point = self._cache.get(key)
        if point is None:
            self.solves += 1
            named = dict(zip(self.paths, map(float, values)))
            if self._span is not None:
                point = self._cache[key] = {"values": named, "linear": self._interpolated(np.asarray(values, float))}
            else:
                scene, doc, model = member_with(self.sc, named)
                point = self._cache[key] = {"scene": scene, "doc": doc, "model": model, "values": named}
        if measure.text not in point:
            point[measure.text] = self._measure(point, measure)
        return point[measure.text]

    def _measure(self, point: dict, measure: Objective) -> tuple:
        kind = measure.kind
        if kind in TIME_DOMAIN:
            sc = point["scene"]
            from smdcli.analysis.sensitivity import sensitivity

            if not self.records:
                if "sensitivity" not in point:
                    point["sensitivity"] = sensitivity(sc, self.paths)
                return time_measure(point["sensitivity"], measure)
            if "records" not in point:  # each record's run at these values
                point["records"] = [sensitivity(scenario_with(under, point["values"]), self.paths)
                                    for _, under in self.records]
            each = [time_measure(s, measure) for s in point["records"]]
            values = np.array([value for value, _, _ in each])
            if self.over == "mean":
                return float(values.mean()), np.mean([gradient for _, gradient, _ in each], axis=0), None
            worst = int(np.argmax(values))
            if each[0][2] is None:  # one piece a record: (record, value, gradient...) rows
                pieces = np.array([[r, value, *gradient] for r, (value, gradient, _) in enumerate(each)])
            else:  # every record's largest peaks in time, largest first
                pieces = np.concatenate([rows for _, _, rows in each])
                pieces = pieces[np.argsort(-pieces[:, 1], kind="stable")]
            return float(values[worst]), each[worst][1].copy(), pieces
        if "linear" not in point:
            model = point["model"]
            if not model.is_linear:
                raise UsageError(f"{self.sc.path}: {kind} needs a linear scene (its receptance); a nonlinear one "
                                 "takes peak_displacement")
            model, sc = model.dense(), point["scene"]
            derived = model_derivatives(sc, model, time_grid(sc.time), self.paths, point["doc"])
            point["linear"] = (model, [(d.of(lambda m: m.dense().M), d.of(lambda m: m.dense().C),
                                        d.of(lambda m: m.dense().K)) for d in derived])
        model, derived = point["linear"]
        if kind in RMS:
            white = self.psd if isinstance(self.psd, float) else 1.0
            profile = None if isinstance(self.psd, float) else self.psd
            try:
                value, gradient = rms(model.M, model.C, model.K, self.input_dof, measure.dof, derived, measure.other,
                                      kind == "rms_acceleration", profile)
            except UsageError as exc:
                raise UsageError(f"{self.sc.path}: {measure.text}: {exc}") from None
            return value * math.sqrt(white), gradient * math.sqrt(white), None
        if self.input_dof is None and kind == "peak_receptance":
            raise UsageError(f"{self.sc.path}: {measure.text} needs a force: the scene is shaken by its support "
                             f"(peak_transmissibility:{self.sc.dof_names[measure.dof]}, or --input DOF)")
        if kind == "peak_transmissibility":
            if model.ground is None:
                raise UsageError(f"{self.sc.path}: {measure.text} needs support motion (a [ground_motion] table); "
                                 "under a force, peak_receptance")
            peaks = transmissibility_peaks(model.M, model.C, model.K, measure.dof, derived)
        else:
            peaks = receptance_peaks(model.M, model.C, model.K, self.input_dof, measure.dof, derived)
        best = int(np.argmax(peaks[:, 1]))
        return float(peaks[best, 1]), peaks[best, 2:].copy(), peaks


def optimize(sc: Scenario, bounds: list[tuple[str, float, float]], objective: str, starts: int = 8,
             input_name: str | None = None, advance=None, subject_to: tuple[str, ...] = (),
             records: tuple = (), over: str = "max", psd=None) -> Optimum:
    """The parameters within bounds minimizing the objective subject to 'MEASURE <= VALUE' constraints, from the
    scenario's own values and a Latin hypercube of starts - 1 more; advance(1) after each start (a progress bar's).
    The rms measures take the input's one-sided PSD in SI (random_vibration.Profile, a white level, or None: white
    noise of level 1): on the support's acceleration where the scene is shaken by it and has no force (and no
    input_name), else on the input's DOF. UsageError where no start finds a point that meets the constraints."""
    from scipy.stats import qmc

    from smdcli.sweep.frequency import input_index

    begin = time.perf_counter()
    if not bounds:
        raise UsageError("smd optimize: give at least one --param PATH=LO:HI")
    if starts < 1:
        raise UsageError(f"--starts {starts}: expected at least 1")
    paths = [p for p, _, _ in bounds]
    check_once(paths)
    base = build(sc)
    elements = dissipators(base)
    goal = read_objective(objective, tuple(base.dofs), str(sc.path), elements)
    lower, upper = np.array([b[1] for b in bounds]), np.array([b[2] for b in bounds])
    doc = tomllib.loads(sc.text)
    initial = np.array([parameter_value(doc, p, sc) for p in paths], dtype=float)
    limits = tuple(read_constraint(text, tuple(base.dofs), str(sc.path), elements) for text in subject_to)
    if psd is not None and not all(m.kind in RMS for m in (goal, *(m for m, _ in limits))):
        raise UsageError(f"--input-psd: only the RMS measures ({', '.join(RMS)}) are under an input PSD; "
                         f"{next(m.text for m in (goal, *(m for m, _ in limits)) if m.kind not in RMS)} is not")
    problem = Problem(sc, paths, goal, None if shaken(base, input_name) else input_index(base, input_name, str(sc.path)),
                      limits,
                      _under_records(sc, records, goal, over), over, psd)
    _check_bounds(problem, initial, lower, upper)
    problem.interpolate(lower, upper)
    width = upper - lower
    inside = np.clip((initial - lower) / width, 0.0, 1.0)
    points = [inside] + list(qmc.LatinHypercube(d=len(paths), seed=0).random(starts - 1))
    before, _, detail_before = problem.evaluate(np.clip(initial, lower, upper))
    scale = abs(before) or 1.0
    runs = []
    for point in points:
        (theta, value), result, history = local_search(problem, np.asarray(point, float), lower, width, scale)
        runs.append((theta, value, result, history))
        if advance is not None:
            advance(1)
    feasible = [r for r in runs if violation(problem, lower + r[0] * width) <= FEASIBLE]
    if not feasible:
        worst = min(runs, key=lambda r: violation(problem, lower + r[0] * width))
        text, excess = max(((t, problem.evaluate(lower + worst[0] * width, m)[0] / limit - 1)
                            for t, (m, limit) in zip(subject_to, limits)), key=lambda pair: pair[1])
        raise UsageError(f"--subject-to {text}: infeasible within the bounds (every search ends {excess:.3g} above "
                         "its limit, relative)")
    runs = sorted(feasible, key=lambda r: r[1])
    optima: list[tuple[np.ndarray, float]] = []
    for theta, value, *_ in runs:
        if all(np.abs(theta - (o - lower) / width).max() > DISTINCT for o, _ in optima):
            optima.append((lower + theta * width, value))
    theta, value, result, history = runs[0]
    # converged: a search that ended here succeeded, or stopped where the first-order conditions hold (SLSQP's line
    # search finding no descent at rounding, on the kink of a minimax)
    converged = any(r[2].success for r in runs if np.abs(r[0] - theta).max() <= DISTINCT) or \
        stationary(problem, theta, lower, width)
    best = lower + theta * width
    value, gradient, detail = problem.evaluate(best)
    on_bound = np.where(theta <= 1e-9, -1, np.where(theta >= 1 - 1e-9, 1, 0))
    peaks = _peaks(detail, goal, problem)
    met = [(text, limit, problem.evaluate(best, m)[0]) for text, (m, limit) in zip(subject_to, limits)]
    met = [(text, limit, value, value >= limit * (1 - 1e-6)) for text, limit, value in met]
    return Optimum(
        scenario=str(sc.path), objective=objective, units=UNITS[goal.kind], parameter=tuple(paths), lower=lower,
        upper=upper, initial=initial, optimum=best, value_before=float(before), value=float(value),
        gradient=np.asarray(gradient, float), on_bound=on_bound, converged=converged,
        message=str(result.message), iterations=int(result.nit), solves=problem.solves,
        history_objective=np.array([h[1] for h in history]),
        history_parameters=np.array([lower + h[0] * width for h in history]).reshape(len(history), len(paths)),
        optima=optima, peaks_before=_peaks(detail_before, goal, problem),
        peaks=peaks, wall_time_s=time.perf_counter() - begin, sc=sc, input_dof=problem.input_dof, constraints=met,
        records=list(zip(map(str, (path for path, _ in problem.records)), problem.record_values(best)))
        if problem.records else [], over=over, problem=problem)


def _as_run(result):
    """A solved run (Result) as time_measure reads a sensitivity run: its histories, its events, no parameters."""
    from types import SimpleNamespace

    from smdcli.solvers.peaks import jump_times

    N, n = result.displacement.shape
    events = [t for t, _, _ in result.nonsmooth.events] if result.nonsmooth is not None else []
    if result.origin is not None and N > 1:
        events += list(jump_times(result.origin[1], result.time))
    empty = np.zeros((0, N, n))
    ground = None if result.ground is None else (result.ground.acceleration, np.zeros((0, N)))
    return SimpleNamespace(time=result.time, displacement=result.displacement, velocity=result.velocity,
                           acceleration=result.acceleration, event_times=np.array(events, dtype=float), parameter=(),
                           d_displacement=empty, d_velocity=empty, d_acceleration=empty, exact_at=None,
                           ground_acceleration=lambda: ground, model=result.origin[1], derivatives=[])


def shaken(model, input_name: str | None) -> bool:
    """Whether the measures' input is the support's acceleration: a scene shaken by its support with no force, and
    no --input DOF named."""
    return input_name is None and model.ground is not None and all(d == GROUND_DOF for d in model.force_dofs)


def _peaks(detail, goal: Objective, problem: Problem) -> np.ndarray:
    """The located peaks drawn and reported: a frequency response's (frequency rad/s, value) or one run's largest in
    time (time s, value) rows; none for the other measures."""
    if detail is None or goal.kind not in PEAKS and (goal.kind not in TIME_PEAK_KINDS or problem.records):
        return np.zeros((0, 2))
    return detail[:, :2].copy()


def _under_records(sc: Scenario, records: tuple, goal: Objective, over: str) -> tuple:
    """(path, the scenario under that record) for each record file: the scenario's [ground_motion] table's file
    replaced, its units and processing kept; UsageError where that cannot be."""
    if not records:
        return ()
    from smdcli.sweep.family import _validated

    if over not in ("max", "mean"):
        raise UsageError(f"--over {over}: expected max or mean")
    if goal.kind not in TIME_DOMAIN:
        raise UsageError(f"--records: {goal.text} is not a time-domain measure (peak_displacement, peak_drift, "
                         "peak_acceleration, residual_displacement)")
    doc = tomllib.loads(sc.text)
    table = doc.get("ground_motion")
    if not isinstance(table, dict) or "file" not in table:
        raise UsageError(f"--records: {sc.path} has no [ground_motion] table with a file to replace")
    out = []
    for record in records:
        path = Path(record)
        if not path.is_file():
            raise UsageError(f"--records: {record}: no such file")
        member = {**doc, "ground_motion": {**table, "file": str(path.resolve())}}
        out.append((path, _validated(member, sc, f"--records {record}")))  # its text the member's own
    return tuple(out)


def _check_bounds(problem: Problem, initial: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> None:
    """Each bound must give a valid scene (the others at their values): UsageError naming the one that does not."""
    for i, path in enumerate(problem.paths):
        for end in (lower[i], upper[i]):
            values = np.clip(initial, lower, upper)
            values[i] = end
            try:
                problem.scene(values)
            except ScenarioError as exc:
                raise UsageError(f"--param {path}={lower[i]:g}:{upper[i]:g}: at {end:g} the scene is not valid "
                                 f"({exc.field}: {exc.message})") from None
