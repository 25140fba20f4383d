"""`smd fit`: the parameters of one or more scenarios that best explain measured response, by bounded nonlinear
least squares whose Jacobian is the exact sensitivities (smdcli.analysis.sensitivity), never finite differences;
with the estimates' covariance, standard errors, correlations and 95 % intervals, and a parameter the data cannot
determine named as such instead of given a meaningless interval.

The residual of channel c of test j at its sample k is w_c (model - measured), the model run from the scenario's
own start and initial state to the data's last time, read at the data's times (the exact solver takes any
increasing grid). The weights default to 1 / each channel's RMS (at least a thousandth of the largest of its
quantity's: default_weights). With sigma^2 = sum r^2 / (m - P) the covariance is
sigma^2 (J^T J)^-1, J the Jacobian at the estimate.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import math
import time as clock
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.analysis.fit_data import Measured, Test, quantity_of
from smdcli.analysis.fit_spans import (MISFIT, RESOLVED, SPAN_TOLERANCE, STALL_DROP, STALL_ITERATIONS, UNEXPLAINED,
                                      NoDerivative, growing_spans, misfit, refusal, stalled_descent, unexplained_share,
                                      within)
from smdcli.analysis.sensitivity import sensitivity
from smdcli.errors import ScenarioError, UsageError
from smdcli.resources import small_blas
from smdcli.scenario import Scenario
from smdcli.sweep.family import member_with

TOLERANCE = 1e-12  # relative reduction of the cost and relative step below which the fit has converged
IDENTIFIABLE = 1e7  # condition number of the column-normalized Jacobian above which a direction is undetermined
JACOBIAN = "exact sensitivities: the scene and its sensitivity equations solved together (smd sensitivity)"


@dataclass
class FitResult:
    """The estimates, their uncertainty, the history of the fit and each test's measured and fitted channels."""

    parameter: tuple[str, ...]
    units: tuple[str, ...]
    initial: np.ndarray
    estimate: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    standard_error: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    confidence_95: np.ndarray  # (P, 2)
    cost: float
    rms_residual: float
    iterations: int
    solves: int
    converged: bool
    message: str
    identifiable: bool
    condition: float
    null_direction: str
    history_cost: np.ndarray
    history_estimate: np.ndarray
    tests: list[Test]
    fitted: list[dict[str, np.ndarray]]  # per test, channel -> the model at the estimate
    jacobian: str = JACOBIAN
    wall_time_s: float = 0.0
    outputs: list[Path] = field(default_factory=list)
    unexplained: float = math.nan  # |weighted residual| / |weighted data|: what the fitted scene leaves unexplained
    warning: str = ""  # where it leaves a misfit (fit_spans.misfit): why the intervals may not be trusted
    retried: str = ""  # where the whole at once stalled: that it was taken again over growing spans, and why


def make_test(sc: Scenario, measured: Measured, channels: tuple[str, ...] | None = None,
              weights: dict[str, float] | None = None) -> Test:
    """A test checked against its scene: every channel names a mass or an element of it, the data start no
    earlier than the scene. Channels and weights default to the scenario's [fit] table's, then to every column
    of the data, each weighted by 1 / its RMS."""
    table = dict(sc.fit)
    channels = channels or table.get("channels")
    weights = weights if weights is not None else dict(table.get("weights", ()))
    from smdcli.model import build

    model = build(sc)
    chosen = tuple(channels) if channels else tuple(measured.channels)
    # springs and dampers, and the hysteretic springs, friction contacts and stops (their forces from the runs' own)
    elements = {e.name for e in model.elements} | {e.path for e in model.nonsmooth}
    for channel in chosen:
        if channel not in measured.channels:
            raise UsageError(f"{measured.file}: no column {channel!r} (its columns: {', '.join(measured.channels)})")
        owner = channel.rsplit(".", 1)[0]
        quantity = quantity_of(channel)
        if (quantity == "force" and owner not in elements) or (quantity != "force" and owner not in model.dofs):
            names = sorted(elements) if quantity == "force" else list(model.dofs)
            what, those = ("element", "elements") if quantity == "force" else ("mass", "masses")
            raise UsageError(f"{measured.file}: column {channel!r} names no {what} of {sc.path} (its {those}: "
                             f"{', '.join(names)})")
    for name in weights or {}:
        if name not in chosen:
            raise UsageError(f"{sc.path}: fit.weights names {name!r}, which is not a fitted channel "
                             f"({', '.join(chosen)})")
    start = sc.time.start
    if measured.time[0] < start - 1e-12 * max(1.0, abs(start)):
        raise UsageError(f"{measured.file}: the data start at t = {measured.time[0]:g} s, before the scenario's "
                         f"start ({start:g} s): the run cannot reach them")
    grid = measured.time if abs(measured.time[0] - start) <= 1e-12 * max(1.0, abs(start)) else \
        np.concatenate([[start], measured.time])
    rows = np.arange(len(grid) - len(measured.time), len(grid))
    given = dict(weights or {})
    default = default_weights(measured, tuple(c for c in chosen if c not in given))
    return Test(sc, measured, chosen, np.array([given[c] if c in given else default[c] for c in chosen]), grid, rows)


WEIGHT_FLOOR = 1e-3  # of the largest RMS among a quantity's channels: the least RMS a default weight divides by


def default_weights(measured: Measured, channels: tuple[str, ...]) -> dict[str, float]:
    """1 / each channel's RMS, the RMS taken as at least WEIGHT_FLOOR of the largest of its quantity's channels: a
    channel the motion has not reached (a long chain's far masses, whose data are the rounding of the run that made
    them) would otherwise be weighted up to 1e15 times, and the fit would chase that rounding (a 100-mass chain's
    spring fitted to its own noise-free response stopped 1.2e-5 off and called half the data unexplained)."""
    rms = {c: float(np.sqrt(np.mean(measured.channels[c] ** 2))) for c in channels}
    largest: dict[str, float] = {}
    for c in channels:
        largest[quantity_of(c)] = max(largest.get(quantity_of(c), 0.0), rms[c])
    for c in channels:
        if largest[quantity_of(c)] == 0.0:
            raise UsageError(f"{measured.file}: column {c!r} is zero throughout, and so is every "
                             f"{quantity_of(c)} column: its default weight, 1 / its RMS, has no value; give it a "
                             "weight ([fit] weights in the scenario) or leave it out ([fit] channels)")
    return {c: 1.0 / max(rms[c], WEIGHT_FLOOR * largest[quantity_of(c)]) for c in channels}


def _model_channels(test: Test, sc: Scenario, params: list[str],
                    built: tuple | None = None) -> tuple[dict, dict, tuple[str, ...]]:
    """Each channel of a test at the scene sc (built: its TOML document and model, where the caller has them): its
    values (N,) and derivatives (P, N) at the data's times, and the sensitivities' notes (where they have none)."""
    s = sensitivity(sc, params, grid=test.grid, peaks=False, built=built)
    dofs = {name: j for j, name in enumerate(s.dof)}
    ground = s.ground_acceleration()
    values, derivatives = {}, {}
    for channel in test.channels:
        owner, quantity = channel.rsplit(".", 1)
        if quantity == "force":
            value, derivative = s.element_tension(owner)
        else:
            j = dofs[owner]
            value, derivative = getattr(s, quantity)[:, j], getattr(s, f"d_{quantity}")[:, :, j]
            if quantity == "acceleration" and ground is not None:  # an accelerometer's: absolute
                value, derivative = value + ground[0], derivative + ground[1]
        values[channel], derivatives[channel] = value[test.rows], derivative[:, test.rows]
    return values, derivatives, s.notes


def fit(tests: list[Test], params: list[str], bounds: dict[str, tuple[float, float]] | None = None,
        max_iterations: int = 100, advance=None) -> FitResult:
    """Fit the shared parameters to every test's data at once; the estimate, its uncertainty and the history;
    advance(1, note) after each solve (a progress bar's)."""
    from scipy.optimize import least_squares

    from smdcli.sweep.family import parameter_value
    from smdcli.sweep.spec import parameter_units

    start = clock.perf_counter()
    first = tomllib.loads(tests[0].scenario.text)
    initial = np.array([parameter_value(first, p, tests[0].scenario) for p in params])
    for test in tests[1:]:  # every scene must hold every parameter (read now: a missing path is named before work)
        doc = tomllib.loads(test.scenario.text)
        for p in params:
            parameter_value(doc, p, test.scenario)
    bounds = dict(bounds or {})
    unknown = [p for p in bounds if p not in params]
    if unknown:
        raise UsageError(f"bounds: {unknown[0]!r} is not a fitted parameter ({', '.join(params)})")
    lower = np.array([bounds[p][0] if p in bounds else (0.0 if v > 0 else -np.inf) for p, v in zip(params, initial)])
    upper = np.array([bounds[p][1] if p in bounds else np.inf for p in params])
    outside = [p for p, v, lo, hi in zip(params, initial, lower, upper) if not lo <= v <= hi]
    if outside:
        raise UsageError(f"bounds: the start {outside[0]} = {initial[params.index(outside[0])]:g} lies outside its "
                         "bounds")
    samples = sum(len(t.rows) * len(t.channels) for t in tests)
    if samples <= len(params):
        raise UsageError(f"{tests[0].measured.file}: {samples} samples cannot determine {len(params)} parameters")
    scale = np.where(initial != 0, np.abs(initial), 1.0)
    refused: list[str] = []  # trial points that are no scene (a kinetic friction force above its breakaway one)
    underived: list[str] = []  # trial points where the response has no derivative
    solves = 0
    size = max(2 * (len(params) + 1) * len(t.scenario.dof_names) for t in tests)

    def attempt(staged: list[Test], theta_start: np.ndarray, budget: int, tolerance: float,
                watch: bool = False) -> tuple:
        """least_squares on these tests' data from theta_start: its answer, the residuals' evaluation (the last
        point's cached), the history of its iterations, and what it stepped back from in its last two iterations
        (its trust region shrunk against them to its end: a graze's wall, not a minimum): a set of "refused"
        (points past the scene) and "underived" (points without a derivative). watch: stop
        where it stalls (fit_spans.stalled_descent: status -2). An answer short of convergence says after how many
        evaluations it stopped. Its start being no scene raises the ScenarioError, its start having no derivative
        NoDerivative."""
        cache: dict[bytes, tuple] = {}
        history: list[tuple[float, np.ndarray]] = []
        stepped_back, backs = [set()], []  # since the last accepted point; each iteration's
        staged_samples = sum(len(t.rows) * len(t.channels) for t in staged)

        def step_back(key: bytes, kind: str) -> tuple:
            """A point with an infinite cost, from which least_squares' trust region steps back (it shrinks the step
            where the residuals are not finite)."""
            stepped_back[0].add(kind)
            cache.clear()
            cache[key] = (np.full(staged_samples, np.inf), None, None)
            return cache[key]

        def evaluate(theta: np.ndarray) -> tuple:
            nonlocal solves
            key = theta.tobytes()
            if key not in cache:
                solves += 1
                first = not history and not cache
                p = theta * scale
                residuals, columns, fitted = [], [], []
                for test in staged:
                    try:
                        sc, doc, model = member_with(test.scenario, dict(zip(params, p)))
                    except ScenarioError as exc:
                        if first:
                            raise
                        refused.append(f"{exc.field}: {exc.message}")  # a step past what the scene allows
                        return step_back(key, "refused")
                    values, derivatives, notes = _model_channels(test, sc, params, (doc, model))
                    finite = np.logical_and.reduce([np.isfinite(d).all(axis=0) for d in derivatives.values()])
                    if not finite.all():
                        why = f"{test.scenario.path}: {'; '.join(notes) or 'a derivative is nan'}"
                        if first:  # its first sample without one, and the span of the data before it
                            at = int(np.argmin(finite))
                            raise NoDerivative(why, float(test.measured.time[at - 1] - test.grid[0]) if at else 0.0,
                                                f"{test.measured.file}'s samples from t = {test.measured.time[at]:.6g} s")
                        # a graze, an impact appearing: the Jacobian there is no number
                        underived.append(", ".join(f"{n} = {v:.6g}" for n, v in zip(params, p)) + f": {why}")
                        return step_back(key, "underived")
                    fitted.append(values)
                    for w, channel in zip(test.weights, test.channels):
                        residuals.append(w * (values[channel] - test.measured.channels[channel]))
                        columns.append(w * derivatives[channel])
                r = np.concatenate(residuals)
                J = np.concatenate(columns, axis=1).T  # (m, P) per unit of each parameter
                cache.clear()  # the last point only: least_squares asks for fun and jac at the same theta
                cache[key] = (r, J, fitted)
                if advance is not None:
                    advance(1, f"cost {0.5 * float(r @ r):.4g}")
            return cache[key]

        def residual(theta):
            return evaluate(theta)[0]

        def jacobian(theta):
            r, J, _ = evaluate(theta)
            history.append((0.5 * float(r @ r), theta * scale))
            backs.append(stepped_back[0])  # what this iteration stepped back from
            stepped_back[0] = set()
            return J * scale

        def watched(intermediate_result):  # least_squares' callback after each iteration (its name tells it so)
            if stalled_descent([c for c, _ in history], unexplained_share(staged, intermediate_result.fun)):
                raise StopIteration

        with np.errstate(all="ignore"), small_blas(size):
            found = least_squares(residual, theta_start, jac=jacobian, bounds=(lower / scale, upper / scale),
                                  method="trf", ftol=tolerance, xtol=tolerance, gtol=tolerance, max_nfev=budget,
                                  x_scale=1.0, callback=watched if watch else None)
        if found.status == -2:
            found.message = (f"stalled after {solves} evaluations (its cost fell less than {100 * STALL_DROP:.0f} % "
                             f"over its last {STALL_ITERATIONS} iterations)")
        elif found.status <= 0:
            found.message = f"stopped after {solves} evaluations"
        return found, evaluate, history, stepped_back[0].union(*backs[-2:])

    theta0 = initial / scale
    spans = growing_spans(tests, len(params))
    # where shorter spans may help, the whole is tried with half the evaluations, and the spans take the rest
    try:
        whole = attempt(tests, theta0, max(1, max_iterations // 2) if spans else max_iterations, TOLERANCE,
                        watch=bool(spans))
        iterations = int(whole[0].njev or 0)
        if spans and whole[0].status <= 0 and max_iterations > solves and \
                unexplained_share(tests, whole[1](whole[0].x)[0]) <= UNEXPLAINED:
            # out of its half while it explains the data all but a little: still descending (a Bouc-Wen spring's k,
            # alpha, beta and c under a sine took 58 evaluations), it takes the rest from its best point
            whole = attempt(tests, whole[0].x, max_iterations - solves, TOLERANCE)
            iterations += int(whole[0].njev or 0)
        found, evaluate, history, stepped = whole
        reason = ("" if not spans or max_iterations - solves <= len(spans) else
                  found.message if found.status <= 0 else
                  "ended stepping back from points past the scene or without a derivative" if stepped else
                  f"left {left}" if (left := misfit(tests, evaluate(found.x)[0], RESOLVED)) else "")
    except NoDerivative as exc:
        if max_iterations < 2:
            raise refusal(exc) from None
        whole, iterations, reason = None, 0, f"had no derivative at its start ({exc.why})"
        spans = spans or [None]
    retried = ""
    if reason:
        theta, done = theta0, 0
        while done < len(spans):
            span = spans[done]
            staged = [w for test in tests if (w := within(test, span)) is not None]
            # a fair share of what is left; the whole, the rest
            budget = max(1, (max_iterations - solves) // (len(spans) - done))
            try:
                spanned = attempt(staged, theta, budget, TOLERANCE if span is None else SPAN_TOLERANCE)
            except NoDerivative as exc:  # a span that ends before the derivative does, first
                when = exc.span
                if when in spans or sum(len(w.rows) * len(w.channels) for test in tests
                                        if (w := within(test, when)) is not None) <= 2 * len(params):
                    raise refusal(exc) from None
                spans.insert(done, when)
                continue
            iterations += int(spanned[0].njev or 0)
            theta, done = spanned[0].x, done + 1
        if whole is None or spanned[0].cost < whole[0].cost:
            found, evaluate, history, stepped = spanned
        spans = [s for s in spans if s is not None]
        retried = (f"over the whole data at once the fit {reason}, so it was taken again over growing spans of "
                   f"the data from their start (" + (f"the first {spans[0]:.4g} s, each next about twice as long, "
                                                      if spans else "") + "then the whole), each from the last one's "
                   "estimate" + ("" if found is spanned[0] else
                                 ", which ended no lower: the first attempt's best point is written"))
    estimate = found.x * scale
    r, J, fitted = evaluate(found.x)
    m, P = len(r), len(params)
    sigma2 = float(r @ r) / (m - P)
    norms = np.linalg.norm(J, axis=0)
    normalized = J / np.where(norms > 0, norms, 1.0)
    _, singular, vt = np.linalg.svd(normalized, full_matrices=False)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else math.inf
    identifiable = condition <= IDENTIFIABLE
    inverse = (vt.T / np.where(singular > singular[0] / IDENTIFIABLE, singular, np.inf) ** 2) @ vt
    covariance = sigma2 * inverse / np.outer(np.where(norms > 0, norms, np.inf), np.where(norms > 0, norms, np.inf))
    standard_error = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    null_direction = ""
    if not identifiable:
        direction = vt[-1]
        involved = np.abs(direction) > 0.1 * np.abs(direction).max()
        standard_error[involved] = np.nan
        covariance[involved, :] = covariance[:, involved] = np.nan
        null_direction = " + ".join(f"{c:+.3g} {p}" for p, c, keep in zip(params, direction, involved) if keep)
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = covariance / np.outer(standard_error, standard_error)
    from scipy.special import stdtrit

    t_value = float(stdtrit(m - P, 0.975))
    confidence = np.stack([estimate - t_value * standard_error, estimate + t_value * standard_error], axis=1)
    converged = bool(found.status > 0)
    message = found.message.rstrip(".") if converged else (
        f"stopped after {solves} evaluations{' (--max-iterations)' if solves >= max_iterations else ''} without "
        f"meeting the tolerance {TOLERANCE:g}; the best point is written")
    message += f"; {retried}" if retried else ""
    if refused:
        message += (f"; {len(refused)} trial point{'s' if len(refused) > 1 else ''} outside what the scene allows "
                    f"stepped back from (the first: {refused[0]})")
    if underived:
        message += (f"; {len(underived)} trial point{'s' if len(underived) > 1 else ''} where the response has no "
                    f"derivative stepped back from (the first: {underived[0]})")
    if not history or not np.array_equal(history[-1][1], estimate):
        history.append((0.5 * float(r @ r), estimate))
    units = tuple(parameter_units(p, tests[0].scenario) or "1" for p in params)
    unexplained = unexplained_share(tests, r)
    left = misfit(tests, r, MISFIT)
    warning = "" if not left else (
        f"the fitted scene leaves {left}: a local minimum (start nearer the answer, or bound "
        "the parameters) or a model that cannot make these data; the standard errors and intervals assume the model "
        "is right")
    if "underived" in stepped and (edge := misfit(tests, r, RESOLVED)):
        # its trust region shrank to nothing against points without a derivative while the data held more to
        # explain: the best fit lies on their edge (two masses' equal starting speeds, a contact starting held, the
        # speed of one fitted: the data's truth on the kink, the fit 2.4e-3 off it with intervals of 1.7e-4)
        warning = (f"the fit ended against trial points where the response has no derivative and leaves {edge}: "
                   "the best fit may lie on their edge (an element starting on the edge between two of its branches, "
                   "a graze), which a fit by derivatives does not reach; the standard errors and intervals take the "
                   "derivative there and do not hold")
    return FitResult(
        parameter=tuple(params), units=units, initial=initial, estimate=estimate, lower=lower, upper=upper,
        standard_error=standard_error, covariance=covariance, correlation=correlation, confidence_95=confidence,
        cost=0.5 * float(r @ r), rms_residual=float(np.sqrt(np.mean(r ** 2))), iterations=iterations,
        solves=solves, converged=converged, message=message, identifiable=identifiable, condition=condition,
        null_direction=null_direction, history_cost=np.array([c for c, _ in history]),
        history_estimate=np.array([e for _, e in history]), tests=tests, fitted=fitted,
        wall_time_s=clock.perf_counter() - start, unexplained=unexplained, warning=warning, retried=retried)
