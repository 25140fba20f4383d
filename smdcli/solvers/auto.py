"""auto: the cheapest method that is exact or accurate enough, and why it was chosen.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from smdcli.model import GROUND_DOF, Model
from smdcli.model.sparse import gershgorin_rate
from smdcli.result import Result
from smdcli.solvers.base import Solver, Tolerances
from smdcli.solvers.exact.hold import unheld
from smdcli.solvers.exact.linear import sparse_action
from smdcli.solvers.exact.modal import modal_applies
from smdcli.solvers.integrators.compiled import StiffnessDetected
from smdcli.solvers.integrators.taylor_series import Taylor, taylor_boundary, taylor_order
from smdcli.solvers.registry import get_solver, solver_class


def _force_kinds(model: Model, exact: bool | None = None) -> str:
    """The forces' types as the scenario names them ("sine and step"); only those (not) exactly integrable if asked."""
    kinds = sorted({kind for kind, s, dof in zip(model.force_types, model.signals, model.force_dofs)
                    if (exact is None or (s.exo() is not None) == exact) and dof != GROUND_DOF})
    return " and ".join(kinds) if len(kinds) < 3 else ", ".join(kinds[:-1]) + " and " + kinds[-1]


def _loads(model: Model) -> str:
    """What drives the scene, for auto's reason: 'free response', 'with sine forces', 'with a pulse ground
    displacement', or both."""
    parts = [f"{_force_kinds(model)} forces"] if any(d != GROUND_DOF for d in model.force_dofs) else []
    if model.ground is not None:
        parts.append(f"a {model.ground.kind} ground {model.ground.quantity}"
                     + (f" (restarted exactly at its {len(model.ground.jumps)} jump(s))" if model.ground.jumps else ""))
    return "with " + " and ".join(parts) if parts else "free response"


STIFFNESS_NOTE_DOFS = 200  # beyond, the reason names stiffness only where the symmetric solver gives it


class Auto(Solver):
    """Closed form or exact for linear scenes; for the rest, explicit unless the trajectory proves stiff."""

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        solver, reason = self.choose(model, grid, tol.rtol)
        abandoned_s = 0.0  # an explicit attempt given up as stiff still cost its time
        if solver is None:  # nonlinear: try explicit with a stiffness watch
            nonlinear = f"nonlinear ({', '.join(model.nonlinear_paths)})"
            why_not = Taylor.unsupported(model)
            explicit = get_solver("DOP853", watch=True, land=True) if why_not else get_solver("taylor", watch=True)
            try:
                result = explicit.solve(model, grid, tol)
                watch = explicit.watch
                if why_not:
                    how = (f"compiled DOP853 (no Taylor series for {why_not}), its steps ending at quadratic dampers' "
                           "velocity reversals")
                    limit = solver_class("DOP853").stability_boundary
                else:
                    order = taylor_order(tol.rtol)
                    how = (f"compiled Taylor series of order {order} (smooth, polynomial elements: its terms by "
                           "recurrence, its steps ending at quadratic dampers' velocity reversals)")
                    limit = round(taylor_boundary(order), 2)
                reason = (f"{nonlinear}; {how}, held by stability on {watch.share:.0%} of {watch.steps} steps "
                          f"(max h*|lambda| = {watch.max_rho:.2f}, limit {limit}): not stiff along this trajectory")
            except StiffnessDetected as stiff:
                abandoned_s = stiff.elapsed_s
                result = get_solver("Radau").solve(model, grid, tol)
                name = "DOP853" if why_not else "Taylor series"
                reason = (f"{nonlinear} and stiff: the explicit {name} was "
                          f"stability-limited on {stiff.fraction:.0%} of its steps by t = {stiff.t:.3g} s "
                          f"(h*|lambda| = {stiff.rho:.2f}); implicit Radau with the analytic Jacobian")
        elif model.nonsmooth:
            from smdcli.solvers.events.drivers import solve_nonsmooth
            from smdcli.solvers.events.piecewise import UNSETTLED

            result = solve_nonsmooth(solver, model, grid, tol)
            if not result.success and solver.name == "exact" and UNSETTLED in result.stats.message:
                # events the exact flow cannot order at one instant (impacts accumulating on a stop while the
                # spring beside it yields and unloads at each): the integrators locate them one by one, and rest
                failed = result.stats.message
                solver, how = _event_integrator(model)
                abandoned_s = result.stats.wall_time_s
                result = solve_nonsmooth(solver, model, grid, tol)
                reason = f"{reason}; but exact {failed}, so {how}"
        else:
            result = solver.solve(model, grid, tol)
            if result.stats.method == "sparse_newmark" and result.success:  # what error it expects: its estimate's
                reason += f" (estimated error {result.stats.stated_accuracy:.2g} of the peak, rtol {tol.rtol:g})"
        stats = dataclasses.replace(result.stats, requested_method=self.name, reason=reason,
                                    wall_time_s=result.stats.wall_time_s + abandoned_s)
        return result.changed(stats=stats)

    def choose(self, model: Model, grid: np.ndarray, rtol: float = Tolerances.rtol) -> tuple[Solver | None, str]:
        """The solver for a model on a grid (at a run's rtol, which sets the Taylor series' order and so its stability)
        and the reason, or (None, '') where the trajectory must decide."""
        if model.nonsmooth:
            return _nonsmooth_choice(model)
        if model.is_sparse:
            return _sparse_choice(model, grid, rtol)
        if model.is_linear:
            # Stiffness does not matter to exact methods, but the user should know an integrator would feel it;
            # not at the price of a general eigenvalue problem larger than the exact solve (smd info computes it).
            told = model.n <= STIFFNESS_NOTE_DOFS or model.proportional_damping
            stiff = (f"; stiff (stiffness ratio {model.stiffness_ratio:.3g}), which an exact method does not feel"
                     if told and model.is_stiff else "")
            if model.n == 1 and not model.is_forced and model.ground is None:
                regime = model.modes.regimes[0]
                return get_solver("closed_form"), f"linear 1-DOF free response ({regime}): closed form, exact to rounding{stiff}"
            if all(s.exo() is not None for s in model.signals):
                forced = f"{_loads(model)} integrated exactly between discontinuities" \
                    if model.is_forced or model.ground is not None else "free response"
                if modal_applies(model):
                    return get_solver("exact"), (f"linear time-invariant, classically damped, {forced}: in modal coordinates "
                                     f"({model.n} exact 1-DOF recurrences), exact to rounding{stiff}")
                if sparse_action(model, grid) is not None:
                    return get_solver("exact"), (f"linear time-invariant, damping not proportional, {forced}: the exponential's "
                                     f"action on the sparse state matrix (cheaper than the dense {2 * model.n}-square "
                                     f"exponential), exact to rounding{stiff}")
                return get_solver("exact"), f"linear time-invariant, {forced}: matrix exponential, exact to rounding{stiff}"
            if model.is_stiff:
                return get_solver("Radau"), (f"linear, but {unheld(model)} has no exact integral, and stiff "
                                 f"(stiffness ratio {model.stiffness_ratio:.3g}): implicit Radau at the scenario's tolerances")
            return get_solver("DOP853"), (f"linear, but {unheld(model)} has no exact integral; not stiff "
                              f"(stiffness ratio {model.stiffness_ratio:.3g}): DOP853 at the scenario's tolerances")
        return None, ""


# The most steps an output step that stability may hold the Taylor series to for auto to give it a sparse scene: its
# steps are at least span |lambda|max / boundary (Gershgorin's bound), where sparse Newmark's follow the motion's
# accuracy alone. benchmarks/sparse_choice.py (docs/solvers.md): on 5,000-mass chains damped stiffly (C = K / 200) the
# series is 3 to 7 times faster up to 11 steps an output step, slower at 29; on a stiff chain whose high modes ring
# (k 1e6 N/m, c 0.5 N s/m: 2.6 steps an output step) it runs where Newmark's estimate misses rtol 1e-6 within its
# 2 million steps.
SPARSE_TAYLOR_STEPS = 16


def _sparse_choice(model: Model, grid: np.ndarray, rtol: float) -> tuple[Solver, str]:
    """A sparse scene's method: the Taylor series on the sparse rows where stability lets it take steps near the
    output's size (at most SPARSE_TAYLOR_STEPS an output step), sparse Newmark otherwise; and why."""
    kind = "linear" if model.is_linear else f"nonlinear ({', '.join(model.nonlinear_paths)})"
    kind = f"{kind}, {model.n} DOFs, sparse: an exact modal solution would hold {model.n}^2 mode-shape entries " \
           f"({8 * model.n ** 2 / 2**30:.2g} GiB) and take n^2 operations per output point"
    unsupported = Taylor.unsupported(model)
    rate = gershgorin_rate(model)
    steps = rate * float(grid[-1] - grid[0]) / taylor_boundary(taylor_order(rtol)) / max(len(grid) - 1, 1)
    stability = f"its stability (|lambda| at most {rate:.3g} 1/s) holds it to no fewer than {steps:.2g} steps an " \
                "output step"
    if unsupported is None and steps <= SPARSE_TAYLOR_STEPS:
        return get_solver("taylor"), (
            f"{kind}; compiled Taylor series on the sparse rows instead, its terms worked out only at the DOFs the "
            f"motion has reached: {stability}, where Newmark's extrapolation takes at least 7")
    why = f"no Taylor series for {unsupported}" if unsupported else f"for the Taylor series {stability}"
    return get_solver("sparse_newmark"), (
        f"{kind}; {why}: Newmark average acceleration on the sparse matrices instead, one factorization reused across "
        "steps, extrapolated over steps h, h/2, h/4 (Romberg) until its error estimate meets rtol")


def _nonsmooth_choice(model: Model) -> tuple[Solver, str]:
    """Exact event to event for a piecewise-linear scene; else the ODE family, event to event: Radau where a law is
    stiff (Law.stiff: a hysteretic variable pinned at its saturation, a regularized friction near zero speed), DOP853
    otherwise."""
    laws = ", ".join(f"{e.path} {e.law_label}" for e in model.nonsmooth)
    if model.is_piecewise_linear and all(s.exo() is not None for s in model.signals):
        return get_solver("exact"), (f"piecewise linear ({laws}), {_loads(model) if model.is_forced or model.ground else 'free'}: "
                         "exact between events, each event located on the exact flow to rounding")
    solver, how = _event_integrator(model)
    if solver.name == "DOP853":
        return solver, f"nonsmooth ({laws}), not linear between events: {how}"
    return solver, f"nonsmooth ({laws}); {how}"


def _event_integrator(model: Model) -> tuple[Solver, str]:
    """The ODE method that takes a nonsmooth scene event to event, and how (after the scene's description)."""
    stiff = [e.path for e in model.nonsmooth if e.law.stiff]
    uncompiled = [e.path for e in model.nonsmooth if not e.law.compiled]
    if uncompiled:  # scipy's pair, stepped from Python: the compiled ones cannot evaluate its tension
        solver = get_solver("scipy:Radau" if stiff else "scipy:DOP853")
        return solver, (f"{', '.join(uncompiled)} has no compiled kernel: {solver.name}, each event located on its "
                        "interpolant, restarted there")
    if stiff:
        return get_solver("Radau"), (f"{', '.join(stiff)} stiff where it saturates or sticks: implicit Radau, each "
                                     "event located on its interpolant, restarted there")
    return get_solver("DOP853"), ("DOP853 at the scenario's tolerances, each event located on its interpolant, "
                                  "restarted there")
