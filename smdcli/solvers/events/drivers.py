"""Scenes with nonsmooth elements: which method takes them, and how.

`exact` solves piecewise-linear scenes event to event (piecewise.py); the ODE family integrates any of them
event to event (integrated.py); the Newmark family steps hysteretic springs by return mapping
(return_mapping.py); every other method refuses, naming the element and the methods that can.

An integrator's run vouches for its energy balance to BALANCE_RTOLS times its rtol of the largest energy, and for a
trajectory error it measures (estimate_error). Local
error control does not bound the global error: the methods without local extrapolation (BDF and the low-order
stiff formulas) leave one that grows as rtol^(2/3), measured at 70 to 600 rtol on the bundled scenes at rtol 1e-8, and
RK23 leaves 15 to 20 rtol. The balance is the run's own a-posteriori measure of that error, so a run that misses
it is rerun at a tighter tolerance chosen from the error's observed growth with the tolerance (assumed 2/3 until
two runs measure it), and says so in a note.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

from smdcli.model import Model
from smdcli.result import Result
from smdcli.solvers.base import Solver, Tolerances
from smdcli.solvers.registry import BY_NAME, METHODS, get_solver

BALANCE_RTOLS = 10.0  # the energy balance a run vouches for, in rtols of the largest energy
BALANCE_AIM = 3.0  # what a rerun aims at: a margin for the error's scatter about its power law
BALANCE_RERUNS = 3
SMALLEST_RTOL = 1e-13  # below this a tolerance is rounding's, not the method's
SLOWEST_GROWTH = 0.3  # the error taken to fall at least as rtol^0.3 (the reruns' growth clamps to 0.3 too)


def nonsmooth_refusal(method: str, model: Model) -> str | None:
    """Why a method cannot take a scene with nonsmooth elements, naming the element and the methods that can."""
    from smdcli.solvers.events.return_mapping import refusal as newmark_refusal

    entry = BY_NAME[method]
    if entry.exact_events:
        return get_solver(method).refuse(model)
    if entry.events:
        uncompiled = [e for e in model.nonsmooth if not e.law.compiled]
        if entry.compiled_modes and uncompiled:
            first = uncompiled[0]
            python = next(m.name for m in METHODS if m.events == entry.events and not m.compiled_modes)
            return (f"{method!r} is compiled, and {first.path}'s law {first.law.name} has no compiled kernel for its "
                    f"smooth tension; try {python!r} (scipy's, stepped from Python) or 'auto'")
        return None
    if entry.return_mapping:
        return newmark_refusal(method, model)
    first = model.nonsmooth[0]
    can = "'exact' (piecewise-linear scenes), 'auto', the ODE family ('DOP853', 'Radau', 'ode45', ...)"
    return (f"{method!r} {entry.refuses_nonsmooth}; {first.path} is {first.law.name} ({first.kind}); "
            f"methods that can: {can}")


def solve_nonsmooth(solver: Solver, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
    """A scene with nonsmooth elements: exact event to event, an ODE method event to event, or the Newmark
    family's return mapping."""
    from smdcli.solvers.events.integrated import solve_events
    from smdcli.solvers.events.return_mapping import solve_return_mapping

    entry = BY_NAME[solver.name]
    if entry.events:  # forces are read at t: a chirp or an expression as exactly as a sine
        run = lambda tol: solve_events(model, grid, tol, solver.name)  # noqa: E731
        if not tol.balance:
            return run(tol)
        result, used, looser = meet_balance(run, tol)
        return estimate_error(run, result, used, looser)
    if entry.return_mapping:
        return solve_return_mapping(model, grid, tol, solver)
    if entry.family == "exact":
        from smdcli.solvers.events.piecewise import solve_exactly

        return solve_exactly(solver.name, model, grid)
    return solver.solve(model, grid, tol)  # auto: it chooses, and comes back here


def meet_balance(run: Callable[[Tolerances], Result], tol: Tolerances) -> tuple[Result, Tolerances, Result | None]:
    """run(tol), rerun at tighter tolerances (at most BALANCE_RERUNS times) until its energy balance is within
    BALANCE_RTOLS rtol of the largest energy: the best successful run, with a note, at the cost of them all, the
    tolerances it was run at, and the run at the next looser tolerance tried (None where there was none)."""
    result = run(tol)
    if not result.success or not tol.rtol:
        return result, tol, None
    tried, failed = [(tol, _balance_rtols(result, tol), result)], ""
    if tried[0][1] <= BALANCE_RTOLS:
        return result, tol, None
    while tried[-1][1] > BALANCE_RTOLS and len(tried) <= BALANCE_RERUNS and tried[-1][0].rtol > SMALLEST_RTOL:
        last_tol, missed, _ = tried[-1]
        growth = 2 / 3
        if len(tried) > 1:  # measured between the last two runs, within the range the methods' orders allow
            (t0, r0, _), (t1, r1, _) = tried[-2], tried[-1]
            growth = min(max(math.log(r0 / r1) / math.log(t0.rtol / t1.rtol), 0.3), 1.5) if r1 > 0 else 1.0
        factor = min(0.5, (BALANCE_AIM / missed) ** (1 / growth))
        rtol = max(last_tol.rtol * factor, SMALLEST_RTOL)
        next_tol = dataclasses.replace(last_tol, rtol=rtol, atol=tol.atol * rtol / tol.rtol)
        rerun = run(next_tol)
        if not rerun.success:
            failed = f"; the rerun at rtol {rtol:.3g} failed ({rerun.stats.message})"
            break
        tried.append((next_tol, _balance_rtols(rerun, tol), rerun))
    used, balance, best = min(tried, key=lambda run: run[1])
    spent = {key: sum(getattr(r.stats, key) for _, _, r in tried)
             for key in ("wall_time_s", "nfev", "njev", "nlu", "steps_accepted", "steps_rejected")
             if all(getattr(r.stats, key) >= 0 for _, _, r in tried)}  # -1: a count the method does not keep
    note = (f"the energy balance at rtol {tol.rtol:g} was off by {tried[0][1]:.3g} rtol of the largest energy (local "
            "error control does not bound the global error); rerun at rtol "
            + ", ".join(f"{t.rtol:.3g}" for t, _, _ in tried[1:]) + failed + f"; kept the run at rtol {used.rtol:.3g}, "
            f"atol {used.atol:.3g}: balance {balance:.3g} rtol" + ("" if balance <= BALANCE_RTOLS else ", still above"))
    stats = dataclasses.replace(best.stats, rtol=tol.rtol, atol=tol.atol, **spent)
    looser = [r for t, _, r in tried if t.rtol > used.rtol]
    return best.changed(stats=stats, notes=(*best.notes, note)), used, (looser[-1] if looser else None)


BLIND_KINKS = ("a kink or event the step control crosses blindly",
               "a tighter rtol, or 'exact' where the scene is piecewise linear, lowers it")


def estimate_error(run: Callable[[Tolerances], Result], result: Result, used: Tolerances,
                   looser: Result | None = None, why: tuple[str, str] = BLIND_KINKS) -> Result:
    """The run with the global error it states measured, not assumed: rerun at a tenth of the tolerances it was run
    at, the difference D is most of its error (an error C rtol^p, p >= SLOWEST_GROWTH, is at most D / (1 - 10^-p));
    where the balance already reran it tighter, the looser run at q = rtol / rtol_looser bounds it at no cost
    (D q^p / (1 - q^p)). A kink
    or an event the step control crosses blindly leaves far more than 10 rtol: DOP853 at rtol 1e-8 on the Bouc-Wen
    benchmark was 7.8e-6 of the peak off while 10 rtol said 1e-7; and a low-order method's global error outgrows its
    tolerance as its steps multiply (`why`: which, and what lowers it). x and v are each measured against their own
    peak. The stated accuracy is the larger of the tolerance's (stated_tolerance) and the estimate; where the
    estimate is the larger, a note says so."""
    from smdcli.solvers.base import stated_tolerance

    if not result.success or not used.rtol or (used.rtol <= SMALLEST_RTOL and looser is None):
        return result
    if looser is not None:  # the looser run's error bounds the kept one's: compared, not rerun
        check, tighter, spent = looser, used, {}
    else:
        tighter = dataclasses.replace(used, rtol=max(used.rtol / 10, SMALLEST_RTOL), atol=(used.atol or 0.0) / 10)
        check = run(tighter)
        spent = {key: getattr(result.stats, key) + getattr(check.stats, key)
                 for key in ("wall_time_s", "nfev", "njev", "nlu", "steps_accepted", "steps_rejected")
                 if getattr(result.stats, key) >= 0 and getattr(check.stats, key) >= 0}
    if not check.success:
        note = (f"the error estimate's rerun at rtol {tighter.rtol:.3g} failed ({check.stats.message}): the stated "
                "accuracy is the tolerance's, 10 sqrt(2n) (rtol + atol / peak), unmeasured")
        return result.changed(stats=dataclasses.replace(result.stats, **spent), notes=(*result.notes, note))
    with np.errstate(invalid="ignore"):
        x = result.displacement
        finite = np.isfinite(x).all(axis=1) & np.isfinite(check.displacement).all(axis=1)
        peaks, differences = [], []
        for mine, other in ((x, check.displacement), (result.velocity, check.velocity)):
            peaks.append(float(np.abs(mine[finite]).max(initial=0.0)))
            differences.append(float(np.abs(mine[finite] - other[finite]).max(initial=0.0)))
    promised = stated_tolerance(result.stats.rtol, result.stats.atol, peaks[0], 2 * x.shape[1], peaks[1])
    q = used.rtol / check.stats.rtol if looser is not None else 10.0  # the kept run's tolerance over the other's
    shrink = q ** SLOWEST_GROWTH
    factor = shrink / (1 - shrink) if looser is not None else 1 / (1 - 1 / shrink)
    measured = factor * max((d / p for d, p in zip(differences, peaks) if p > 0), default=0.0)
    notes = result.notes
    if measured > promised:
        against = check.stats.rtol if looser is not None else tighter.rtol
        notes = (*notes, f"the run's error, measured against a run at rtol {against:.3g}, is about "
                         f"{measured:.3g} of the peak, {measured / promised:.3g} times what rtol {result.stats.rtol:g} "
                         f"promises ({why[0]}): the stated accuracy is the measured one; {why[1]}")
    stats = dataclasses.replace(result.stats, stated_accuracy=max(promised, measured), **spent)
    return result.changed(stats=stats, notes=notes)


def _balance_rtols(result: Result, tol: Tolerances) -> float:
    """The run's energy balance, its largest residual over the largest energy, in rtols of the requested tolerance."""
    return result.nonsmooth.balance().max_relative_residual / tol.rtol
