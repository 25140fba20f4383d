"""The explicit Runge-Kutta pairs at compiled speed: RK23/ode23, RK45/ode45, DOP853 (smdcli.kernels.erk).

They take the steps scipy's classes of the same names take (the scipy-driven ones stay available as
`scipy:RK45` ... for cross-checks) at about 0.1-0.3 us per right-hand side instead of ~25 us.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from smdcli.kernels import tableaus
from smdcli.model import Model
from smdcli.result import Result, SolverStats
from smdcli.solvers.base import MAX_STEPS, Solver, Tolerances, cuts, divergence_bound, make_result

COMPILING_NOTE = ("smd: compiling kernels, once per install (half a minute to two, by what the scene needs; later "
                  "runs load them from numba's cache)")
_announced = False


def announce_compile(dispatcher, quiet: bool = False) -> None:
    """Say on stderr that kernels are about to compile, once per process, where no cached code exists."""
    global _announced
    from smdcli.kernels.compiler import is_cached

    if _announced or quiet or is_cached(dispatcher):
        return
    _announced = True
    print(COMPILING_NOTE, file=sys.stderr, flush=True)


def run_kernel(model: Model, method: int, grid: np.ndarray, y0: np.ndarray, rtol: float, atol: np.ndarray,
               max_steps: int, bound: float, boundary: float = 0.0, breakpoints: bool = True, fixed_h: float = 0.0,
               land: bool = False):
    """Run the compiled pair from y0 over the grid: (status, out rows, int counts, float statistics).
    fixed_h > 0: steps of that size, no error control; land: steps end at quadratic dampers' velocity reversals."""
    from smdcli.kernels import erk
    from smdcli.kernels.arrays import model_arrays
    from smdcli.kernels.rhs import work_size

    arrays = model_arrays(model)
    out = np.full((len(grid), len(y0)), np.nan)
    out[0] = y0
    counts, floats = np.zeros(5, dtype=np.int64), np.zeros(5)
    status = erk.integrate(arrays, method, np.asarray(y0, dtype=float), np.asarray(grid, dtype=float),
                           cuts(model, grid, breakpoints), float(rtol), np.asarray(atol, dtype=float),
                           int(max_steps), float(bound), float(boundary), out, counts, floats,
                           np.zeros(work_size(arrays)), float(fixed_h), bool(land))
    return status, out, counts, floats


def _tiny_model() -> Model:
    return Model(dofs=("m",), M=np.eye(1), C=np.zeros((1, 1)), K=np.eye(1), x0=np.ones(1), v0=np.zeros(1))


def _tiny_run(family: str) -> None:
    """One small run of a kernel family, so that it is compiled or loaded."""
    from smdcli.kernels.arrays import model_arrays

    tiny, grid, y0 = _tiny_model(), np.array([0.0, 1e-3]), np.array([1.0, 0.0])
    entry = _entry(family)
    if family == "rhs":  # called from Python by the Fortran integrators
        entry(model_arrays(tiny), 0.0, y0, False, np.zeros(2), np.zeros(2), np.zeros((1, 1)))
        return
    if family == "erk":
        run_kernel(tiny, tableaus.RK45, grid, y0, 1e-3, np.full(2, 1e-6), 10, 1e8)
        return
    if family == "yielding":  # a damped elastoplastic mass pushed past yield by a ramp
        from smdcli import scenario
        from smdcli.model import build
        from smdcli.solvers.events.yielding import solve_yielding

        scene = scenario.parse('[time]\nend = 1.0\n[[mass]]\nname = "m"\nm = 1.0\n[[spring]]\nconnects = ["ground", '
                               '"m"]\nlaw = "elastoplastic"\nk = 1.0\nfy = 0.1\n[[damper]]\nconnects = ["ground", "m"]\n'
                               'c = 0.5\n[[force]]\non = "m"\ntype = "table"\nt = [0.0, 1.0]\nvalues = [0.0, 1.0]\n')
        solve_yielding(build(scene), np.linspace(0.0, 1.0, 3))
        return
    if family == "taylor":
        from smdcli.kernels.taylor import FLOATS, start_run

        arrays = model_arrays(tiny)
        entry(arrays, grid, grid, 1e-3, 1e-6, 10, 1e8, 0.0, np.zeros((3, 2, 1)), False, len(grid),
              start_run(arrays, y0, 8), np.zeros(5, dtype=np.int64), np.zeros(FLOATS))
        return
    if family == "return_mapping":
        from smdcli.kernels.rhs import work_size

        arrays, one = model_arrays(tiny), np.ones((1, 1))
        entry(arrays, one, one, one, one, np.zeros(1, dtype=np.int64), np.array([[1.0, 1.0, 0.0, 0.0, 0.0]]),
              np.array([0.0, 0.0, 0.25, 0.5]), np.ones(1), np.zeros(1), np.zeros(1), grid, np.zeros((2, 1)),
              np.zeros((2, 1)), 1e-3, 10, 1e8, np.zeros(4), np.zeros((4, 1)), np.zeros((4, 1)), np.zeros((4, 1)),
              np.zeros((4, 1)), np.zeros((4, 1)), np.zeros((4, 4)), np.zeros(2, dtype=np.int64), np.zeros(1),
              np.zeros(work_size(arrays)))
        return
    if family == "banded":  # a 2-DOF chain with a cubic spring and a quadratic damper, two steps
        pair, one = np.array([[0, 1]], dtype=np.int64), np.ones(1)
        band = np.array([[2.0, 1.0], [-1.0, 0.0]])
        factors = band[None] + np.array([[[1e6, 1e6], [0.0, 0.0]]])
        effective = factors.copy()
        from smdcli.kernels.banded import cholesky

        cholesky(factors[0])
        entry(np.ones((1, 2)), band, band, effective, factors, np.array([1e-3]), np.zeros(1, dtype=np.int64), 2,
              grid, np.ones(1, dtype=np.bool_), np.ones((1, 1)), np.ones((1, 2, 1)), np.ones((2, 1)), pair, one,
              pair, one, np.arange(2, dtype=np.int64), np.array([0, 1], dtype=np.int64), np.ones(2), np.zeros(2),
              np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(3, dtype=np.int64), np.zeros(1))
        return
    if family in ("sensitivity", "implicit_sensitivity"):  # the state alone (no parameter's stencil), two outputs
        from smdcli.kernels.rhs import work_size
        from smdcli.kernels.compiler import model_tuple

        arrays = model_arrays(tiny)
        entry(arrays, model_tuple([], arrays), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros((0, 1, 1)),
              np.zeros(0, dtype=np.bool_), y0.copy(), grid, grid, 1e-3,
              np.full(2, 1e-6), 10, np.zeros((2, 2)), np.zeros((2, 2)), np.zeros(work_size(arrays)),
              np.zeros(3, dtype=np.int64), np.zeros(1), *((np.inf,) if family == "sensitivity" else ()))
        return
    if family.startswith("modes:"):
        from smdcli.kernels.rhs import work_size

        arrays = model_arrays(tiny)
        entry(arrays, tableaus.RK45, y0.copy(), 0.0, np.array([1e-3]), np.array([5e-4]), grid, 1, 1e-3,
              np.full(2, 1e-6), 10, 1e8, -np.inf, -1, np.zeros((2, 2)), np.zeros((2, 1)), np.zeros((2, 0)),
              np.zeros(5, dtype=np.int64), np.zeros(5), np.zeros(work_size(arrays)), 0.0)
        return
    arrays, out = model_arrays(tiny), np.zeros((2, 2))
    if family == "fixed":
        entry(arrays, sys.modules[entry.__module__].GENERALIZED_ALPHA, np.zeros(4), y0, grid, grid, 1e-3, 10, 1e8, out, np.zeros(4, dtype=np.int64), np.zeros(2),
              np.zeros(2))
    elif family == "stiff":
        entry(arrays, tableaus.TRBDF2, y0, grid, grid, 1e-3, np.full(2, 1e-6), 10, 1e8, out, np.zeros(5, dtype=np.int64),
              np.zeros(1), np.zeros(2), 0.0)
    else:
        entry(arrays, y0, grid, grid, 1e-3, np.full(2, 1e-6), 10, 1e8, out, np.zeros(5, dtype=np.int64), np.zeros(1),
              np.zeros(2), 0.0)


def _entry(family: str):
    """The dispatcher whose compiled code stands for a kernel family's (only its module is imported)."""
    import importlib

    module, name = {"erk": ("erk", "integrate"), "fixed": ("fixed", "march"), "stiff": ("stiff", "integrate"),
                    "radau": ("radau", "integrate"), "bdf": ("bdf", "integrate"), "rhs": ("rhs", "state_rhs"),
                    "return_mapping": ("return_mapping", "march"), "banded": ("banded", "march"),
                    "taylor": ("taylor", "integrate"), "yielding": ("yielding", "run"),
                    "sensitivity": ("sensitivity", "integrate"),
                    "implicit_sensitivity": ("implicit_sensitivity", "integrate")
                    }.get(family, (family.removeprefix("modes:"), "integrate_mode"))  # modes:MODULE: its mode kernel
    return getattr(importlib.import_module(f"smdcli.kernels.{module}"), name)


KERNEL_FAMILIES = ("erk", "fixed", "stiff", "radau", "bdf", "rhs", "modes:events", "modes:radau", "modes:bdf",
                   "modes:stiff", "return_mapping", "banded", "taylor", "yielding", "sensitivity",
                   "implicit_sensitivity")
_warmed: set[str] = set()
# two chains of kernel families that share compiled parts, each compiled in a child process of its own, about equal
# (on a 2-core Intel Xeon under numba's generic target, 2026-12-03, the modes' families free after their integrators:
# stiff 58 s, erk 16, modes:events 9, fixed 8, banded 6, yielding 57; radau 55, bdf 13, taylor 29, sensitivity 54,
# return_mapping 10: 155 s and 161 s, where they were 305 s and 301 s before kernels stopped passing literals)
COMPILE_CHAINS = (("stiff", "modes:stiff", "erk", "rhs", "modes:events", "fixed", "banded", "yielding"),
                  ("radau", "modes:radau", "bdf", "modes:bdf", "taylor", "sensitivity", "implicit_sensitivity",
                   "return_mapping"))


def compile_side_by_side(families=KERNEL_FAMILIES) -> None:
    """Compile the families that numba's cache lacks in two child processes at once where there are two cores (a
    test session's start, CI's first step); each child writes numba's cache, from which warm() then loads them."""
    import os
    import subprocess

    missing = [family for family in families if not cached(family)]
    chains = [[family for family in chain if family in missing] for chain in COMPILE_CHAINS]
    if (os.cpu_count() or 1) < 2 or not all(chains):
        return
    print("\nsmd: compiling kernels in two processes (a few minutes, once per install)", file=sys.stderr, flush=True)
    children = [subprocess.Popen([sys.executable, "-c", f"from smdcli.solvers.integrators.compiled import warm; warm(*{chain!r})"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for chain in chains]
    for child in children:
        child.wait()


def cached(family: str) -> bool:
    """Whether a kernel family's code is compiled in this process or in numba's cache (warm then costs no compile)."""
    from smdcli.kernels.compiler import is_cached

    return is_cached(_entry(family))


def warm(*families: str) -> None:
    """Compile kernel families (erk, fixed, stiff, radau, bdf, rhs, and modes:events, modes:radau ... for nonsmooth
    scenes' modes; default erk) or load them from numba's cache
    before any clock starts, saying so once if compiling."""
    for family in families or ("erk",):
        if family in _warmed:
            continue
        entry = _entry(family)
        if not getattr(entry, "signatures", True):  # not compiled yet (plain Python under NUMBA_DISABLE_JIT=1 has none)
            announce_compile(entry)
            _tiny_run(family)
        _warmed.add(family)


@dataclass(frozen=True)
class Watch:
    """What the stiffness watch saw: steps watched, stability-limited, the largest h|lambda|, and where it stopped."""

    steps: int
    limited: int
    max_rho: float
    stopped_at: float | None = None
    fraction: float = 0.0
    rho: float = 0.0

    @property
    def share(self) -> float:
        """Share of all watched steps that were stability-limited."""
        return self.limited / self.steps if self.steps else 0.0


class StiffnessDetected(Exception):
    """The watch stopped an explicit run: most recent steps were held by stability, not accuracy."""

    def __init__(self, watch: Watch, elapsed_s: float):
        self.watch, self.elapsed_s = watch, elapsed_s
        self.t, self.fraction, self.rho = watch.stopped_at, watch.fraction, watch.rho
        super().__init__(f"stability-limited on {watch.fraction:.0%} of recent steps at t = {watch.stopped_at:.4g} s")


def failure_text(status: int, max_steps: int, bound: float) -> str:
    """What a kernel's status code means, for the run's message."""
    from smdcli.kernels import erk

    return {
        erk.TOO_SMALL_STEP: "Required step size is less than spacing between numbers.",
        erk.STEP_BUDGET: f"more than {max_steps} steps",
        erk.NOT_FINITE: "the state became NaN or infinite",
        erk.PAST_BOUND: f"the state grew past {bound:.3g}",
    }[status]


def explicit_outcome(solver, status: int, counts: np.ndarray, floats: np.ndarray, elapsed: float, tol: Tolerances,
                     max_steps: int, bound: float) -> tuple[SolverStats, float | None]:
    """An explicit kernel's run read back (erk's counters and floats): the solver's watch set, StiffnessDetected
    raised where the watch stopped it, else its statistics and where it failed (None if it did not)."""
    from smdcli.kernels import erk

    solver.watch = Watch(int(counts[erk.WATCHED]), int(counts[erk.LIMITED]), float(floats[erk.MAX_RHO]))
    if status == erk.STIFF:
        solver.watch = Watch(solver.watch.steps, solver.watch.limited, solver.watch.max_rho, float(floats[erk.STIFF_T]),
                             float(floats[erk.STIFF_FRACTION]), float(floats[erk.STIFF_RHO]))
        raise StiffnessDetected(solver.watch, elapsed)
    failure = None if status == erk.OK else failure_text(status, max_steps, bound)
    t_reached = float(floats[erk.T_REACHED])
    stats = SolverStats(
        method=solver.name, requested_method=solver.name, reason="", rtol=tol.rtol, atol=tol.atol,
        wall_time_s=elapsed, success=failure is None,
        message="ok" if failure is None else f"failed at t = {t_reached:.6g} s: {failure}",
        nfev=int(counts[erk.NFEV]), njev=0, nlu=0, steps_accepted=int(counts[erk.ACCEPTED]),
        steps_rejected=int(counts[erk.REJECTED]),
    )
    return stats, None if failure is None else t_reached


class CompiledRK(Solver):
    """An explicit Runge-Kutta pair run by the compiled kernel, restarted at every force discontinuity."""

    compiled = True
    tableau: ClassVar[str]  # the name of a method id in smdcli.kernels.tableaus (the registry's setting)
    stability_boundary: ClassVar[float]
    watch: Watch | None = None

    def __init__(self, watch: bool = False, land: bool = False):
        self.watching, self.landing = watch, land

    @property
    def kernel_method(self) -> int:
        """The kernel's id of this pair (smdcli.kernels.tableaus)."""
        return getattr(tableaus, self.tableau)

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        warm()
        start = time.perf_counter()
        y0 = np.concatenate([model.x0, model.v0])
        bound = divergence_bound(model, grid)
        max_steps = tol.max_steps or MAX_STEPS
        boundary = self.stability_boundary if self.watching else 0.0
        status, out, counts, floats = run_kernel(model, self.kernel_method, grid, y0, tol.rtol,
                                                 np.full(len(y0), tol.atol), max_steps, bound, boundary,
                                                 tol.breakpoints, land=self.landing)
        stats, t_failed = explicit_outcome(self, status, counts, floats, time.perf_counter() - start, tol, max_steps,
                                           bound)
        n = model.n
        return make_result(model, grid, out[:, :n], out[:, n:], stats, t_failed=t_failed)


class CompiledStiff(Solver):
    """Radau IIA 5 (smdcli.kernels.radau), NDF (smdcli.kernels.bdf) or a low-order formula of smdcli.kernels.stiff
    run compiled with the analytic Jacobian, restarted at every force discontinuity."""

    compiled = True
    implicit = True
    order = 2
    kernel_method: ClassVar[str]  # RADAU5, NDF, or the name of a method id in smdcli.kernels.stiff

    @property
    def kernel_family(self) -> str:
        """The kernel family (see warm) that runs this method."""
        return {"RADAU5": "radau", "NDF": "bdf"}.get(self.kernel_method, "stiff")

    def integrate(self, arrays, *args):
        """Run the kernel: (y0, grid, cuts, rtol, atol, max_steps, bound, out, counts, floats, work, fixed_h)."""
        from smdcli.kernels import bdf, radau, stiff

        if self.kernel_method == "RADAU5":
            return radau.integrate(arrays, *args)
        if self.kernel_method == "NDF":
            return bdf.integrate(arrays, *args)
        return stiff.integrate(arrays, getattr(tableaus, self.kernel_method), *args)

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        from smdcli.kernels import stiff
        from smdcli.kernels.arrays import model_arrays
        from smdcli.kernels.rhs import work_size

        warm(self.kernel_family)
        start = time.perf_counter()
        y0 = np.concatenate([model.x0, model.v0]).astype(float)
        bound = divergence_bound(model, grid)
        max_steps = tol.max_steps or MAX_STEPS
        arrays = model_arrays(model)
        out = np.full((len(grid), len(y0)), np.nan)
        out[0] = y0
        counts, floats = np.zeros(5, dtype=np.int64), np.zeros(1)
        status = self.integrate(arrays, y0, np.asarray(grid, dtype=float), cuts(model, grid, tol.breakpoints),
                                float(tol.rtol), np.full(len(y0), tol.atol), int(max_steps), float(bound), out, counts,
                                floats, np.zeros(work_size(arrays)), 0.0)
        failure = None if status == stiff.OK else failure_text(status, max_steps, bound)
        t_reached = float(floats[stiff.T_REACHED])
        stats = SolverStats(
            method=self.name, requested_method=self.name, reason="", rtol=tol.rtol, atol=tol.atol,
            wall_time_s=time.perf_counter() - start, success=failure is None,
            message="ok" if failure is None else f"failed at t = {t_reached:.6g} s: {failure}",
            nfev=int(counts[stiff.NFEV]), njev=int(counts[stiff.NJEV]), nlu=int(counts[stiff.NLU]),
            steps_accepted=int(counts[stiff.ACCEPTED]), steps_rejected=int(counts[stiff.REJECTED]),
        )
        n = model.n
        return make_result(model, grid, out[:, :n], out[:, n:], stats, t_failed=None if failure is None else t_reached)
