"""Incremental dynamic analysis (Vamvatsikos and Cornell 2002): a scene run under one record scaled up step by
step to collapse. The intensity measures (IM) of a record and the engineering demand parameters (EDP) of a run,
the collapse rules, and the hunt-and-fill trace of one record; the fractiles across records.

Every IM here is proportional to the record's scale (a spectral ordinate, a peak acceleration or velocity), so a
run at intensity x is the record scaled by x over its own intensity.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field

import numpy as np

from smdcli.errors import SolverFailed, UsageError

IMS = ("sa", "pga", "pgv")
EDPS = ("max_drift_ratio", "peak_displacement", "residual_drift", "peak_acceleration")
SLOPE_LIMIT = 0.2  # a run whose secant slope from the run below falls under this share of the first's has collapsed
HUNT_GROWTH = 2.0  # each hunting step doubles the intensity
HUNT_START = 0.25  # the first run at this share of the record's own intensity
HUNT_STEPS = 16  # hunting steps before a record is said never to collapse
FRACTILE_LEVELS = 50  # EDP levels the fractile curves are read at, from 0 to the collapse limit


@dataclass(frozen=True)
class Intensity:
    """An IM: its kind, a spectral ordinate's period (s, None: the first mode's) and damping ratio."""

    kind: str
    text: str
    period: float | None = None
    damping: float = 0.05

    @property
    def units(self) -> str:
        """m/s^2 for Sa and PGA, m/s for PGV."""
        return "m/s" if self.kind == "pgv" else "m/s^2"


@dataclass(frozen=True)
class Demand:
    """An EDP: its kind and DOF (peak_displacement, peak_acceleration)."""

    kind: str
    text: str
    dof: int = -1

    @property
    def units(self) -> str:
        """The EDP's units."""
        return {"max_drift_ratio": "1", "residual_drift": "m", "peak_displacement": "m",
                "peak_acceleration": "m/s^2"}[self.kind]


@dataclass(frozen=True)
class Collapse:
    """The collapse rule's limit on the largest drift ratio or displacement (None: instability and slope only)."""

    text: str
    drift: float | None = None
    displacement: float | None = None


@dataclass
class Trace:
    """One record's IDA: its runs in the order run (IM, EDP, collapsed, wall time), its collapse intensity."""

    record: str
    own_im: float
    im: list = field(default_factory=list)
    edp: list = field(default_factory=list)
    collapse: list = field(default_factory=list)
    wall: list = field(default_factory=list)
    collapse_im: float = math.nan


def read_intensity(text: str) -> Intensity:
    """'sa', 'sa:T=<s>[,zeta=<ratio>]', 'pga' or 'pgv'; UsageError naming what is wrong."""
    kind, _, rest = text.partition(":")
    if kind not in IMS:
        raise UsageError(f"--im {text}: expected sa, sa:T=<s>[,zeta=<ratio>], pga or pgv")
    if not rest:
        return Intensity(kind, text)
    found = re.fullmatch(r"T=([^,]+)(?:,zeta=(.+))?", rest)
    if kind != "sa" or not found:
        raise UsageError(f"--im {text}: expected sa:T=<s>[,zeta=<ratio>] (sa:T=1.2,zeta=0.05)")
    try:
        period, damping = float(found.group(1)), float(found.group(2) or 0.05)
    except ValueError:
        raise UsageError(f"--im {text}: expected numbers for T and zeta") from None
    if not (period > 0 and math.isfinite(period) and 0 <= damping < 1):
        raise UsageError(f"--im {text}: expected T > 0 s and 0 <= zeta < 1")
    return Intensity(kind, text, period, damping)


def read_demand(text: str, dofs: tuple[str, ...], has_building: bool) -> Demand:
    """'max_drift_ratio', 'residual_drift', 'peak_displacement:<dof>' or 'peak_acceleration:<dof>'."""
    kind, _, dof = text.partition(":")
    if kind not in EDPS:
        raise UsageError(f"--edp {text}: expected one of max_drift_ratio, residual_drift, peak_displacement:<dof>, "
                         "peak_acceleration:<dof>")
    if kind in ("max_drift_ratio", "residual_drift"):
        if dof or not has_building:
            raise UsageError(f"--edp {text}: {kind} is a storey's: it needs a [building] table (storey_heights)"
                             if not has_building else f"--edp {text}: {kind} takes no DOF")
        return Demand(kind, text)
    if dof not in dofs:
        raise UsageError(f"--edp {text}: expected {kind}:<dof>, a DOF of the scene ({', '.join(dofs)})")
    return Demand(kind, text, dofs.index(dof))


def read_collapse(text: str | None, has_building: bool) -> Collapse:
    """'drift=<ratio>' or 'displacement=<m>' (None: instability and the slope rule only)."""
    if text is None:
        return Collapse("instability or slope")
    found = re.fullmatch(r"(drift|displacement)=(.+)", text)
    try:
        limit = float(found.group(2)) if found else math.nan
    except ValueError:
        limit = math.nan
    if not found or not (limit > 0 and math.isfinite(limit)):
        raise UsageError(f"--collapse {text}: expected drift=<ratio> or displacement=<m>, a positive limit")
    if found.group(1) == "drift":
        if not has_building:
            raise UsageError(f"--collapse {text}: a drift limit needs a [building] table (storey_heights)")
        return Collapse(text, drift=limit)
    return Collapse(text, displacement=limit)


def record_intensity(times: np.ndarray, acceleration: np.ndarray, im: Intensity, first_period: float) -> float:
    """The IM of a record (m/s^2, sampled, linear between samples) at scale 1: Sa exact between samples (smd
    spectrum's), PGA at the samples (exact: the record is linear between them), PGV the peak of the exact integral
    (piecewise quadratic: located where the acceleration crosses zero inside a step)."""
    a = np.asarray(acceleration, dtype=float)
    if im.kind == "pga":
        return float(np.abs(a).max())
    if im.kind == "sa":
        from smdcli.analysis.spectrum import response_spectrum

        period = im.period if im.period is not None else first_period
        return float(response_spectrum(times, a, np.array([period]), np.array([im.damping])).Sa[0, 0])
    h = np.diff(times)
    v = np.concatenate([[0.0], np.cumsum(h * (a[:-1] + a[1:]) / 2)])
    peak = float(np.abs(v).max())
    crossing = np.flatnonzero(a[:-1] * a[1:] < 0)
    for k in crossing:  # v(tau) = v_k + a_k tau + (a_k+1 - a_k) tau^2 / (2 h): its extremum where a = 0
        tau = a[k] / (a[k] - a[k + 1]) * h[k]
        peak = max(peak, abs(v[k] + a[k] * tau + (a[k + 1] - a[k]) * tau * tau / (2 * h[k])))
    return peak


def solved(sc, edp: Demand):
    """One run of a record at a scale, with what its EDP and collapse read (element forces, storeys), not its energy
    balance: a yielding frame's on the compiled exact kernel (solvers.events.yielding: the same events and states as
    the general exact solver, 100 times faster; the absolute accelerations' peaks located on its solution); any
    other scene as `smd simulate` solves it. SolverFailed where the run fails (a diverging, collapsing frame)."""
    from smdcli.analysis.forces import element_forces
    from smdcli.model import build, time_grid
    from smdcli.solvers.run import failure_message, solve_scenario

    model, grid = build(sc), time_grid(sc.time)
    result = None
    if sc.solver.method in ("auto", "exact"):
        from smdcli.solvers.events.yielding import solve_yielding

        result = solve_yielding(model, grid, locate_acceleration=edp.kind == "peak_acceleration")
    if result is None:
        result = solve_scenario(sc, model, grid, None, None, None)
    if not result.success:
        raise SolverFailed(failure_message(sc, model, result), result=result)
    result = result.changed(origin=(sc, model), elements=element_forces(model, result.displacement, result.velocity,
                                                                        result.nonsmooth))
    if sc.building is not None:
        from smdcli.analysis.storeys import storeys

        result = result.changed(storeys=storeys(result, sc.building))
    return result


def demand(result, edp: Demand) -> float:
    """The EDP of a solved run: peaks located on the solution between samples (an absolute acceleration where the
    solver located it, else at the samples)."""
    from smdcli.solvers.peaks import result_peaks

    if edp.kind == "max_drift_ratio":
        return float(result.storeys.peak_drift_ratio.max())
    if edp.kind == "residual_drift":
        return float(np.abs(result.storeys.residual_drift).max())
    if edp.kind == "peak_displacement":
        return float(result_peaks(result, absolute=False)[edp.dof])
    if result.located_acceleration is not None:
        return float(result.located_acceleration[edp.dof])
    return float(np.abs(result.absolute("acceleration")[:, edp.dof]).max())


def over_limit(result, rule: Collapse) -> bool:
    """Whether a run passes the collapse rule's limit."""
    from smdcli.solvers.peaks import result_peaks

    if rule.drift is not None:
        return bool(result.storeys.peak_drift_ratio.max() > rule.drift)
    if rule.displacement is not None:
        return bool(result_peaks(result, absolute=False).max() > rule.displacement)
    return False


def trace(record: str, own_im: float, run, rule: Collapse, tolerance: float, runs: int) -> Trace:
    """One record's hunt and fill: run(scale) -> (EDP, over the limit) or SolverFailed (dynamic instability).
    Geometric steps from HUNT_START of the record's own IM, doubling, to the first collapse; bisection between the
    last run standing (lo) and the first collapsed (hi) until (hi - lo) / lo <= tolerance; then `runs` more, each
    at the middle of the largest gap between the intensities run below lo (the slope rule applies to the hunt and
    the bisection, whose runs rise above the curve so far; a fill run collapses only by the limit or instability).
    The collapse intensity is the final bracket's middle."""
    found = Trace(record, own_im)

    def at(im: float, fill: bool = False) -> bool:
        begin = time.perf_counter()
        try:
            edp, over = run(im / own_im)
            collapsed = over or not math.isfinite(edp)
        except SolverFailed:
            edp, collapsed = math.nan, True
        if not collapsed and not fill:  # the slope rule, for a run above the curve so far: the secant from the run
            # standing below it, against the first's (a fill run lies below runs standing: the rule does not apply)
            standing = sorted((i, e) for i, e, c in zip(found.im, found.edp, found.collapse) if not c and i < im)
            below = standing[-1] if standing else (0.0, 0.0)
            first = standing[0] if standing else (im, edp)
            slope, first_slope = (edp - below[1]) / (im - below[0]), first[1] / first[0]
            collapsed = bool(first_slope > 0 and slope < SLOPE_LIMIT * first_slope)
        found.im.append(float(im))
        found.edp.append(float(edp))
        found.collapse.append(bool(collapsed))
        found.wall.append(time.perf_counter() - begin)
        return collapsed

    im, lo, hi = HUNT_START * own_im, 0.0, math.nan
    for _ in range(HUNT_STEPS):
        if at(im):
            hi = im
            break
        lo, im = im, im * HUNT_GROWTH
    if math.isnan(hi):
        return found  # never collapsed within the hunt
    while (hi - lo) > tolerance * (lo if lo > 0 else hi):
        middle = 0.5 * (lo + hi)
        if at(middle):
            hi = middle
        else:
            lo = middle
    found.collapse_im = 0.5 * (lo + hi)
    for _ in range(runs):
        below = sorted(set([0.0] + [i for i in found.im if i <= lo]))  # every run's intensity, standing or not
        gaps = np.diff(below)
        if not len(gaps):
            break
        k = int(np.argmax(gaps))
        at(0.5 * (below[k] + below[k + 1]), fill=True)
    return found


def fractiles(traces: list[Trace], limit: float | None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """EDP levels (FRACTILE_LEVELS from 0 to the collapse limit, or to the largest EDP seen) and the 16 %, 50 % and
    84 % fractiles across records of the IM each record's curve reaches them at (linear interpolation along the
    curve of its runs standing, from the origin; capped at its collapse IM), numpy's default percentile."""
    top = limit if limit is not None else max((e for t in traces for e, c in zip(t.edp, t.collapse)
                                               if not c and math.isfinite(e)), default=1.0)
    levels = np.linspace(0.0, top, FRACTILE_LEVELS)
    curves = []
    for t in traces:
        standing = sorted((i, e) for i, e, c in zip(t.im, t.edp, t.collapse) if not c)
        im = np.array([0.0] + [i for i, _ in standing])
        edp = np.maximum.accumulate(np.array([0.0] + [e for _, e in standing]))  # a curve read as it first reaches
        cap = t.collapse_im if math.isfinite(t.collapse_im) else np.inf
        reached = np.interp(levels, edp, im, right=np.inf) if len(im) > 1 else np.full(len(levels), np.inf)
        curves.append(np.minimum(reached, cap))
    curves = np.array(curves)
    return levels, {f"im_{q}": np.percentile(curves, q, axis=0) for q in (16, 50, 84)}
