"""The Taylor series solver (smdcli.kernels.taylor) run compiled: its order and stability boundary for a tolerance,
and a large output zeroed on the second core ahead of the kernel.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from contextlib import contextmanager

import numpy as np

from smdcli.model import Model
from smdcli.result import Result
from smdcli.solvers.base import MAX_STEPS, Solver, Tolerances, cuts, divergence_bound, make_result
from smdcli.solvers.integrators.compiled import Watch, explicit_outcome, warm


# A Taylor step's tolerance: this share of rtol and atol. The steps' errors add up over a run (the global error is
# about 10 times the step's on the bundled nonlinear scenes), and the series' cost grows only with the log of its
# accuracy: a ten-thousandth, not a hundredth, takes the 100-mass chain at rtol 1e-6 to 1.7e-12 of its peak (was
# 6.5e-10) with order 17 and 122 steps instead of 13 and 144, about a tenth more time.
TAYLOR_STEP_SHARE = 1e-4
ZEROED_IN_ONE_PASS = 8 << 20  # bytes of a Taylor run's output past which zeroed_ahead zeroes it ahead of the kernel


def taylor_order(rtol: float) -> int:
    """The series' order for a run's tolerance: about 0.7 ln(1/(step's tolerance)), between 8 and 30 (an order costs
    about a right-hand side; higher orders take longer steps)."""
    return int(min(30, max(8, math.ceil(0.7 * math.log(1 / max(rtol * TAYLOR_STEP_SHARE, 1e-16))))))


@functools.lru_cache(maxsize=None)
def taylor_boundary(order: int) -> float:
    """Where on the negative real axis the order's truncated exponential sum_k z^k / k! first reaches 1 in size."""
    series = 1.0 / np.cumprod(np.concatenate([[1.0], np.arange(1.0, order + 1)]))  # 1 / k!, rising powers of z
    crossings = [root.real for level in (1.0, -1.0) for root in np.roots((series - np.eye(order + 1)[0] * level)[::-1])
                 if abs(root.imag) < 1e-9 and root.real < -1e-9]
    return float(-max(crossings))


class Taylor(Solver):
    """Taylor series of the motion, its coefficients by recurrence, summed compiled (smdcli.kernels.taylor)."""

    compiled = True
    order = None
    rms_error_norm = False  # each step's terms are held to atol + rtol times x's and v's peaks, component by component
    watch: Watch | None = None

    def __init__(self, watch: bool = False):
        self.watching = watch

    @staticmethod
    def unsupported(model: Model) -> str | None:
        """What in the scene has no series here (nonsmooth elements, a force shape without one), or None."""
        if model.nonsmooth:
            return "nonsmooth elements"
        for kind, signal in zip(model.force_types, model.signals):
            if not signal.series:
                return f"a {kind} force"
        return None

    def refuse(self, model: Model) -> str | None:
        """Scenes with something that has no series: say what, and what to use instead."""
        what = self.unsupported(model)
        return f"'taylor' has no series for {what}; try 'DOP853' or 'auto'" if what else None

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        from smdcli.kernels import taylor
        from smdcli.kernels.arrays import model_arrays

        warm("taylor")
        start = time.perf_counter()
        n = model.n
        out = taylor.aligned_empty(3 * len(grid) * n).reshape((3, len(grid), n))  # x, v, a
        # the kernel writes zeros where the motion has not reached, unless out is larger than the caches: then its
        # zeros are written in one pass a chunk, on the second core, from here on (the 1,000-mass chain's 24 MB: its
        # rows' own zeros took 1.5 ms)
        with zeroed_ahead(out if out.nbytes > ZEROED_IN_ONE_PASS else None) as run_zeroed:
            y0 = np.concatenate([model.x0, model.v0]).astype(float)
            bound = divergence_bound(model, grid)
            max_steps = tol.max_steps or MAX_STEPS
            order = taylor_order(tol.rtol)
            boundary = taylor_boundary(order) if self.watching else 0.0
            out[0, 0], out[1, 0] = model.x0, model.v0  # and a's row 0, the kernel
            arrays = model_arrays(model)
            counts, floats = np.zeros(5, dtype=np.int64), np.zeros(taylor.FLOATS)
            run = taylor.start_run(arrays, y0, order)
            arguments = (arrays, np.asarray(grid, dtype=float), cuts(model, grid, tol.breakpoints),
                         float(tol.rtol) * TAYLOR_STEP_SHARE, float(tol.atol) * TAYLOR_STEP_SHARE, int(max_steps),
                         float(bound), float(boundary), out)
            status = run_zeroed(lambda zeroed, ready: taylor.integrate(*arguments, zeroed, ready, run, counts, floats))
        stats, t_failed = explicit_outcome(self, status, counts, floats, time.perf_counter() - start, tol, max_steps,
                                           bound)
        x, v, (x_low, x_high, v_low, v_high) = out[0], out[1], floats[taylor.EXTREMES:taylor.FLOATS].tolist()
        found = ((x, (x_low, x_high)), (v, (v_low, v_high))) if status == taylor.OK else ()
        return make_result(model, grid, x, v, stats, t_failed=t_failed, acceleration=out[2],
                           found_extremes=found)


ZEROING_CHUNKS = 16  # of a large output, zeroed in turn: a chunk's zeros (1.5 MB of the 1,000-mass chain's) take
# the pool thread 0.06-0.15 ms, so that the kernel waits at most that long where it catches up; 8 and 32, slower


@contextmanager
def zeroed_ahead(out: np.ndarray | None):
    """Zeroing out's rows 1.. (its second axis; row 0 is the caller's and the kernel's) on a pool thread, a chunk at a
    time, from the block's start (interrupts.alongside), so that a large output's zeros take the second core's time
    while the block works out the run's arguments and the kernel sums into the rows before them (the 1,000-mass
    chain's 24 MB: 1.2 ms of zeros, where its kernel takes 1.1). The block gets run: run(integrate) calls
    integrate(zeroed, rows_ready), again while it returns NEED_ROWS (the kernel stops before rows not yet zeroed and
    goes on in the next call), and returns its status, with NaN from where a failed run stopped to the end. Without
    out (an output within the caches), nothing is zeroed and run calls integrate(False, all the rows) once."""
    from smdcli.interrupts import alongside
    from smdcli.kernels.taylor import NEED_ROWS, OK, STIFF

    if out is None:
        yield lambda integrate: integrate(False, sys.maxsize)
        return
    rows = out.shape[1]
    ends = sorted({1, *(min(max(2, rows * share // ZEROING_CHUNKS), rows) for share in range(1, ZEROING_CHUNKS + 1))})

    with alongside([functools.partial(out[:, a:b].fill, 0.0) for a, b in zip(ends, ends[1:])]) as ready:
        def run(integrate) -> int:
            needed = 0  # the chunk that zeroes the rows after those ready
            while True:
                done = ready(needed)
                reached = ends[done + 1]
                status = integrate(True, reached)
                if status != NEED_ROWS or reached == rows:
                    break
                needed = done + 1
            if status not in (OK, STIFF):  # the kernel wrote NaN up to the rows it had; the rest, once zeroed
                ready(len(ends) - 2)
                out[:, reached:] = np.nan
            return status

        yield run
