"""`smd compare-solvers`: many methods over ladders of tolerances and steps, against a reference.

Error is the largest displacement difference from the reference over the output grid and all
DOFs, divided by the reference's peak displacement. The reference is the exact solution for a
linear scene; for a nonlinear one, Radau and DOP853 at rtol 1e-12, whose difference is reported
as the reference's own error.

Must not import: cli.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from smdcli.errors import ScenarioError, UsageError
from smdcli.model import Model
from smdcli.progress import bar, silent
from smdcli.result import Result
from smdcli.scenario import Scenario
from smdcli.solvers.base import TIME_ONCE_S, Tolerances, stated_tolerance
from smdcli.solvers.registry import EXACT_NAMES, method_problem, names
from smdcli.commands.compare_nonsmooth import (NONSMOOTH_RTOLS, VARIANTS, cannot_represent, nonsmooth_defaults,
                                               refusals, run_energy, smoothed, split_variant, verdict)

DEFAULTS = names(compare="adaptive") + names(compare="fixed")  # the registry's compare-solvers groups
DEFAULT_RTOLS = tuple(10.0 ** -k for k in range(3, 11))
# Steps as h * omega_max: either side of RK4's limit (2.83) and central difference's (2), then finer.
DEFAULT_H_OMEGA = (3.0, 2.6, 2.1, 1.9, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02)
ATOL_PER_RTOL = 1e-3
STEP_BUDGET = 200_000  # for methods driven from Python (scipy's): about 200 us a step
NONSMOOTH_STEP_BUDGET = 20_000  # on a nonsmooth scene, where a step count past this is the failure to chart
COMPILED_STEP_BUDGET = 50_000_000  # for compiled methods, about 1 us a step: ode23s at rtol 1e-10 takes ~15 million


@dataclass
class Run:
    """One method at one setting: its error and its cost."""

    method: str
    adaptive: bool
    rtol: float
    atol: float
    dt: float
    h_omega: float  # dt * omega_max (fixed step), NaN otherwise
    error: float  # max |x - x_ref| / peak |x_ref|; NaN when the run failed
    energy_residual: float  # the run's own energy balance residual, relative (NaN when it failed)
    growth: float  # peak |x| / peak |x_ref| over what was computed
    wall_time_s: float
    nfev: int
    njev: int
    nlu: int
    steps_accepted: int
    steps_rejected: int
    success: bool
    message: str


@dataclass
class Comparison:
    """Every run, the reference and what it cost, for one scenario."""

    scenario: Scenario
    model: Model
    grid: np.ndarray
    reference: Result
    reference_method: str
    reference_error: float
    omega_max: float
    breakpoints: bool
    runs: list[Run] = field(default_factory=list)
    refused: dict[str, str] = field(default_factory=dict)  # method -> why it cannot take this (nonsmooth) scene

    @property
    def exact_point(self) -> tuple[float, float] | None:
        """(wall time, stated accuracy) of the exact solution, a point of its own on the chart; None if nonlinear."""
        s = self.reference.stats
        if s.method != "exact":
            return None
        return s.wall_time_s, s.stated_accuracy


def parse_methods(text: str | None, model: Model | None = None) -> list[str]:
    """A comma list of method names (a nonsmooth scene's may end /tanh or /penalty: run on its friction or stops
    smoothed), checked against the registry; by default every method, or for a nonsmooth scene the ODE family and
    three of them on its smoothed laws."""
    if not text:
        if model is not None and model.nonsmooth:
            return list(nonsmooth_defaults(model))
        return list(DEFAULTS)
    methods = [m.strip() for m in text.split(",") if m.strip()]
    for m in methods:
        variant, base = split_variant(m)
        if variant is not None and variant not in VARIANTS:
            raise UsageError(f"--methods: {m!r}: expected /tanh or /penalty after a method, found /{variant}")
        problem = method_problem(base)
        if problem:
            raise UsageError(f"--methods: {problem}")
        if base in EXACT_NAMES:
            raise UsageError(f"--methods: {m!r} is not compared: the reference is the exact solution or a tight run")
    if not methods:
        raise UsageError("--methods: expected a comma-separated list of methods, found nothing")
    return methods


def parse_tolerances(text: str | None, model: Model | None = None) -> list[tuple[float, float]]:
    """'rtol[/atol],...' pairs; atol defaults to rtol * 1e-3."""
    if not text:
        ladder = NONSMOOTH_RTOLS if model is not None and model.nonsmooth else DEFAULT_RTOLS
        return [(r, r * ATOL_PER_RTOL) for r in ladder]
    pairs = []
    for item in text.split(","):
        parts = item.strip().split("/")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise UsageError(f"--tolerances: expected rtol or rtol/atol numbers, found {item.strip()!r}") from None
        if len(values) > 2 or not all(math.isfinite(v) and v > 0 for v in values):
            raise UsageError(f"--tolerances: expected positive rtol or rtol/atol, found {item.strip()!r}")
        pairs.append((values[0], values[1] if len(values) == 2 else values[0] * ATOL_PER_RTOL))
    return pairs


def parse_steps(text: str | None, omega_max: float, span: float) -> list[float]:
    """Fixed steps in seconds; by default a ladder of h * omega_max (or of the span, for a scene without stiffness)."""
    if not text:
        if omega_max > 0:
            return [c / omega_max for c in DEFAULT_H_OMEGA]
        return [span / n for n in (50, 100, 200, 500, 1000, 2000)]
    steps = []
    for item in text.split(","):
        try:
            value = float(item)
        except ValueError:
            raise UsageError(f"--steps: expected step sizes in seconds, found {item.strip()!r}") from None
        if not (math.isfinite(value) and value > 0):
            raise UsageError(f"--steps: expected positive step sizes, found {item.strip()!r}")
        steps.append(value)
    return steps


def reference_solution(model: Model, grid: np.ndarray) -> tuple[Result, str, float]:
    """(reference, its name, its estimated error relative to its peak)."""
    from smdcli.solvers.dispatch import solve

    if model.is_linear:
        exact = solve(model, grid, "exact", Tolerances())
        return exact, "exact (matrix exponential)", 0.0
    if model.is_piecewise_linear and all(s.exo() is not None for s in model.signals):
        exact = solve(model, grid, "exact", Tolerances())
        return exact, "exact (event to event, every event located on the exact flow)", 0.0
    tight = Tolerances(rtol=1e-12, atol=1e-14)
    radau = solve(model, grid, "Radau", tight)
    dop = solve(model, grid, "DOP853", tight)
    if not (radau.success and dop.success):
        failed = radau if not radau.success else dop
        raise UsageError(f"the reference run ({failed.stats.method}) failed: {failed.stats.message}")
    peak = float(np.abs(radau.displacement).max()) or 1.0
    return radau, "Radau rtol 1e-12 (checked against DOP853 rtol 1e-12)", \
        float(np.abs(radau.displacement - dop.displacement).max() / peak)


def plan(methods: list[str], tolerances, steps) -> list[tuple[str, Tolerances]]:
    """Every (method, settings) pair to run, loosest first within each method."""
    from smdcli.solvers.registry import get_solver

    jobs = []
    for m in methods:
        if get_solver(split_variant(m)[1]).adaptive:
            jobs += [(m, Tolerances(rtol=r, atol=a)) for r, a in sorted(tolerances, reverse=True)]
        else:
            jobs += [(m, Tolerances(dt=h)) for h in sorted(steps, reverse=True)]
    return jobs


def compare(sc: Scenario, model: Model, grid: np.ndarray, methods: list[str], tolerances, steps,
            repeats: int = 3, breakpoints: bool = True, budget: int | None = None,
            progress: Callable[..., None] = silent) -> Comparison:
    """Run the plan; failures are recorded, never raised. A method that ran out of budget skips its tighter rungs.
    The step budget is STEP_BUDGET for Python-driven methods and COMPILED_STEP_BUDGET for compiled ones, unless
    `budget` says otherwise."""
    from smdcli.solvers.dispatch import solve
    from smdcli.solvers.registry import get_solver

    reference, ref_name, ref_error = reference_solution(model, grid)
    if reference.stats.method == "exact":  # a point on the chart too: timed as the runs are, median of repeats
        times = [reference.stats.wall_time_s] + [solve(model, grid, "exact", Tolerances()).stats.wall_time_s
                                                 for _ in range(max(1, repeats))]
        reference = reference.changed(stats=dataclasses.replace(
            reference.stats, wall_time_s=statistics.median(times[1:])))
    omega_max = model.omega_max
    out = Comparison(sc, model, grid, reference, ref_name, ref_error, omega_max, breakpoints,
                     refused=refusals(model, DEFAULTS, methods))
    peak = float(np.abs(reference.displacement).max()) or 1.0
    states = 2 * reference.displacement.shape[1]  # what the adaptive methods' error norm runs over
    exhausted: set[str] = set()
    span = float(grid[-1] - grid[0])
    for method, tol in plan(methods, tolerances, steps):
        progress(0, f"{method} {'dt ' + format(tol.dt, '.3g') if tol.dt else 'rtol ' + format(tol.rtol, '.0e')}")
        solver = get_solver(split_variant(method)[1])
        adaptive = solver.adaptive
        compiled = solver.compiled and not model.nonsmooth  # a nonsmooth scene is driven from Python, event by event
        allowed = budget or (COMPILED_STEP_BUDGET if compiled else NONSMOOTH_STEP_BUDGET if model.nonsmooth
                             else STEP_BUDGET)
        tol = Tolerances(rtol=tol.rtol, atol=tol.atol, dt=tol.dt, max_steps=allowed, breakpoints=breakpoints,
                         balance=False)  # each method charted as it is, no rerun to meet its energy balance
        if method in exhausted or (tol.dt and span / tol.dt > allowed):
            needed = f"{math.ceil(span / tol.dt)} steps" if tol.dt else "more steps than a looser tolerance"
            out.runs.append(_skipped(method, adaptive, tol, omega_max, f"skipped: needs {needed}, budget {allowed}"))
            progress(1)
            continue
        variant, base = split_variant(method)
        scene = model if variant is None else smoothed(model, variant, reference)
        times, result = [], None
        try:
            for _ in range(max(1, repeats)):
                result = solve(scene, grid, base, tol)
                times.append(result.stats.wall_time_s)
                if result.stats.wall_time_s > TIME_ONCE_S or not result.success:
                    break
        except ScenarioError as exc:  # a method that cannot take the scene says so, and is not charted
            out.runs.append(_skipped(method, adaptive, tol, omega_max, cannot_represent(exc.message)))
            progress(1)
            continue
        s = result.stats
        if not s.success and "steps" in s.message:
            exhausted.add(method)
        with np.errstate(invalid="ignore"):
            computed = np.abs(result.displacement[np.isfinite(result.displacement).all(axis=1)])
        growth = float(computed.max() / peak) if computed.size else math.nan
        error = float(np.abs(result.displacement - reference.displacement).max() / peak) if s.success else math.nan
        energy = run_energy(scene, result).max_relative_residual if s.success else math.nan
        within = CONVERGENCE_SLACK * stated_tolerance(tol.rtol, tol.atol, peak, states) if adaptive else 0.0
        failure = verdict(result, error, energy, growth, reference, variant, within) if s.success else s.message
        out.runs.append(Run(
            method=method, adaptive=adaptive, rtol=tol.rtol, atol=tol.atol, dt=tol.dt or math.nan,
            h_omega=(tol.dt * omega_max) if tol.dt else math.nan, error=error, energy_residual=energy, growth=growth,
            wall_time_s=statistics.median(times), nfev=s.nfev, njev=s.njev, nlu=s.nlu,
            steps_accepted=s.steps_accepted, steps_rejected=s.steps_rejected, success=not failure,
            message=failure or s.message))
        progress(1)
    _judge_convergence(out.runs, peak, states)
    return out


CONVERGENCE_SLACK = 10.0  # times what a tolerance lets the global error reach (stated_tolerance)


def _judge_convergence(runs: list[Run], peak: float, states: int) -> None:
    """An adaptive method that at its tightest tolerance is still off the reference by more than that tolerance allows,
    and no nearer than at its loosest, converges to something else (a smoothed law, a missed event's branch): each
    of its runs is failed, saying so, never 'ok' (penalty contact on the bouncing ball sat at 1.7e-2 from rtol 1e-3
    to 1e-9)."""

    by_method: dict[str, list[int]] = {}
    for i, r in enumerate(runs):
        if r.adaptive and r.success:
            by_method.setdefault(r.method, []).append(i)
    for method, indices in by_method.items():
        if len(indices) < 2:
            continue
        tightest = min(indices, key=lambda i: runs[i].rtol)
        loosest = max(indices, key=lambda i: runs[i].rtol)
        allowed = CONVERGENCE_SLACK * stated_tolerance(runs[tightest].rtol, runs[tightest].atol, peak, states)
        # at its tightest still off by more than it allows, and no nearer than at its loosest: not converging
        if runs[tightest].error <= allowed or runs[tightest].error < 0.1 * runs[loosest].error:
            continue
        variant = split_variant(method)[0]
        law = f"the {variant} law" if variant else "another solution"
        message = (f"converges to another law ({law}): {runs[tightest].error:.2g} of the peak off the reference at "
                   f"rtol {runs[tightest].rtol:.0e}, where the tolerance allows {allowed:.1g}, and no nearer at "
                   f"rtol {runs[loosest].rtol:.0e}")
        for i in indices:
            runs[i] = dataclasses.replace(runs[i], success=False, message=message)


def _skipped(method, adaptive, tol, omega_max, message) -> Run:
    return Run(method=method, adaptive=adaptive, rtol=tol.rtol, atol=tol.atol, dt=tol.dt or math.nan,
               h_omega=(tol.dt * omega_max) if tol.dt else math.nan, error=math.nan, energy_residual=math.nan,
               growth=math.nan,
               wall_time_s=math.nan, nfev=0, njev=0, nlu=0, steps_accepted=0, steps_rejected=0, success=False,
               message=message)


# ----------------------------------------------------------------- reports
def as_dict(c: Comparison) -> dict:
    """Plain data for --json."""
    exact = c.exact_point
    return {
        "scenario": c.scenario.path, "reference": c.reference_method, "reference_error": c.reference_error,
        "exact": None if exact is None else {"wall_time_s": exact[0], "stated_accuracy": exact[1]},
        "omega_max_rad_s": c.omega_max, "breakpoints": c.breakpoints,
        "runs": [{k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in asdict(r).items()}
                 for r in c.runs],
    }


def format_table(c: Comparison) -> str:
    """The terminal table: one line per run."""
    lines = [f"{c.scenario.path}: reference {c.reference_method}"
             + (f", its own error {c.reference_error:.1e}" if c.reference_error else "")
             + f"; omega_max {c.omega_max:.4g} rad/s; error = max |x - x_ref| / peak |x_ref|"
             + ("" if c.breakpoints else "; NOT restarted at force discontinuities (--no-breakpoints)"),
             f"{'method':<19}{'setting':>17}{'error':>10}{'energy':>10}{'time [ms]':>11}{'nfev':>9}{'njev':>7}"
             f"{'nlu':>8}{'steps':>9}{'rejected':>9}  status"]
    for r in c.runs:
        setting = f"rtol {r.rtol:.0e}/{r.atol:.0e}" if r.adaptive else f"h*w {r.h_omega:.3g}" if c.omega_max \
            else f"dt {r.dt:.3g}"
        error = f"{r.error:.2e}" if r.success else "-"
        energy = f"{r.energy_residual:.2e}" if r.success else "-"
        ms = f"{1e3 * r.wall_time_s:.1f}" if math.isfinite(r.wall_time_s) else "-"
        status = "ok" if r.success else f"FAILED: {r.message}"
        lines.append(f"{r.method:<19}{setting:>17}{error:>10}{energy:>10}{ms:>11}{r.nfev:>9}{r.njev:>7}{r.nlu:>8}"
                     f"{r.steps_accepted:>9}{r.steps_rejected:>9}  {status}")
    exact = c.exact_point
    if exact is not None:
        lines.append(f"{'exact':<19}{'-':>17}{exact[1]:>10.2e}{'-':>10}{1e3 * exact[0]:>11.1f}{'-':>9}{'-':>7}"
                     f"{'-':>8}{'-':>9}{'-':>9}  the reference; error column: its stated accuracy")
    lines.append("energy: the run's energy balance residual over the largest energy (its own accuracy check)")
    return "\n".join(lines)


def write_hdf5(path: Path, c: Comparison) -> None:
    """One file with every run's figures and the reference (kind = "compare")."""
    import h5py

    from smdcli.io.atomic import atomic_path
    from smdcli.io.hdf5 import axis, with_scales, write_header

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_header(f, c.scenario, "compare")
        f.attrs["reference"] = c.reference_method
        f.attrs["reference_error"] = c.reference_error
        f.attrs["omega_max_rad_s"] = c.omega_max
        f.attrs["breakpoints"] = c.breakpoints
        runs = f.create_group("runs")
        n = len(c.runs)
        index = axis(runs, "run", np.arange(n))
        string = h5py.string_dtype("utf-8")
        for name in ("method", "message"):
            runs.create_dataset(name, data=np.array([getattr(r, name) for r in c.runs], dtype=object), dtype=string)
        units = {"rtol": "1", "atol": "m", "dt": "s", "h_omega": "1", "error": "1", "energy_residual": "1",
                 "growth": "1", "wall_time_s": "s"}
        for name in ("rtol", "atol", "dt", "h_omega", "error", "energy_residual", "growth", "wall_time_s"):
            ds = runs.create_dataset(name, data=np.array([getattr(r, name) for r in c.runs], dtype=float))
            ds.attrs["units"] = units[name]
        for name in ("nfev", "njev", "nlu", "steps_accepted", "steps_rejected"):
            runs.create_dataset(name, data=np.array([getattr(r, name) for r in c.runs], dtype=np.int64))
        for name in ("adaptive", "success"):
            runs.create_dataset(name, data=np.array([getattr(r, name) for r in c.runs], dtype=bool))
        for ds in runs.values():
            if ds.name != index.name:
                ds.dims[0].attach_scale(index)
        ref = f.create_group("reference")
        ref.attrs["method"] = c.reference_method
        ref.attrs["wall_time_s"] = c.reference.stats.wall_time_s
        ref.attrs["stated_accuracy"] = c.reference.stats.stated_accuracy
        t = axis(ref, "time", c.grid)
        t.attrs["units"] = "s"
        x = with_scales(ref.create_dataset("displacement", data=c.reference.displacement), t,
                         axis(ref, "dof", c.reference.dofs))
        x.attrs["units"] = "m"


def stability_limits(methods: list[str]) -> dict[str, float]:
    """Each fixed-step method's largest stable h * omega on an undamped scene."""
    from smdcli.solvers.registry import get_solver

    limits = {}
    for m in methods:
        solver = get_solver(split_variant(m)[1])
        if not solver.adaptive:
            limits[m] = solver.omega_limit()  # with the method's default parameters
    return limits


def run_and_write(path: str | Path, out: str | Path, methods: str | None = None, tolerances: str | None = None,
                  steps: str | None = None, repeats: int = 3, breakpoints: bool = True, plots: bool = True,
                  progress: bool = False) -> tuple[Comparison, list[Path]]:
    """The whole command: validate everything first, run, then write HDF5 and charts atomically."""
    from smdcli.commands.simulate import prepare
    from smdcli.io.folders import output_folder

    sc, model, grid = prepare(path)
    method_list = parse_methods(methods, model)
    tolerance_list = parse_tolerances(tolerances, model)
    step_list = parse_steps(steps, model.omega_max, float(grid[-1] - grid[0]))
    if repeats < 1:
        raise UsageError(f"--repeats: expected an integer >= 1, found {repeats}")
    out_dir = output_folder(out)
    jobs = len(plan(method_list, tolerance_list, step_list))
    with bar("comparing", jobs, progress) as tick:
        comparison = compare(sc, model, grid, method_list, tolerance_list, step_list, repeats=repeats,
                             breakpoints=breakpoints, progress=tick)
    stem = sc.stem
    written = [out_dir / f"{stem}_compare.h5"]
    from smdcli.io.atomic import together

    with together():  # the files appear together, or none of them
        write_hdf5(written[0], comparison)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.compare import energy_precision_figure, stability_figure, work_precision_figure

            title = sc.title or stem
            save_figure(work_precision_figure(comparison, title), out_dir / f"{stem}_work_precision.png")
            written.append(out_dir / f"{stem}_work_precision.png")
            save_figure(energy_precision_figure(comparison, title), out_dir / f"{stem}_energy_precision.png")
            written.append(out_dir / f"{stem}_energy_precision.png")
            limits = stability_limits(method_list)
            if model.nonsmooth:
                from smdcli.plots.compare import failure_map_figure

                save_figure(failure_map_figure(comparison, title), out_dir / f"{stem}_failures.png")
                written.append(out_dir / f"{stem}_failures.png")
            elif limits:
                save_figure(stability_figure(comparison, title, limits), out_dir / f"{stem}_stability.png")
                written.append(out_dir / f"{stem}_stability.png")
    return comparison, written
