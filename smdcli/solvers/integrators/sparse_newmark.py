"""Large scenes at the speed of a structural code: Newmark's average acceleration on the sparse M, C and K, one
sparse LU of its effective stiffness reused across the steps, extrapolated to sixth order.

The average-acceleration rule (the trapezoidal rule on the second-order system) is symmetric, so on a stretch
where the forces are smooth its global error is a series in even powers of the step: c2 h^2 + c4 h^4 + ... Run
at steps h, h/2 and h/4, each landing on every output point and force discontinuity (the method restarts
there, from equilibrium with the force's right limit), and Romberg's table cancels the first two terms:

    T22 = x2 + (x2 - x1) / 3,  T32 = x3 + (x3 - x2) / 3,  T33 = T32 + (T32 - T22) / 15.

|T33 - T32| estimates the error of T32 (fourth order), which bounds that of T33 (sixth order): the error this
run states. Where it is above rtol of the peak (and atol), the steps are made finer by the fourth root of the
excess and the three runs repeat; where twice the steps will do, the pass takes the last pass's two finer runs as
its coarser two, and only its finest is new (the 10,000-mass chain's second pass: 8,000 steps, not 14,000).
Cubic springs and quadratic dampers enter each step's equation through modified Newton iterations on the same
LU, refactored at the tangent only where they converge slowly.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from smdcli.model import Model
from smdcli.result import Result, SolverStats
from smdcli.solvers.base import MAX_STEPS, Solver, Tolerances, cuts, make_result

LEVELS = (1, 2, 4)  # the steps of Romberg's table, as divisions of the coarsest
STEP_SAFETY = 1.3  # finer than the fourth root asks, so the rerun lands inside the tolerance
ROMBERG_VALUES = 2 ** 16  # values of each run the table combines at once


class NewtonFailed(Exception):
    """A step's nonlinear equation did not converge: where."""

    def __init__(self, t: float):
        super().__init__(t)
        self.t = t


class SparseNewmark(Solver):
    """Newmark average acceleration on sparse matrices, Richardson-extrapolated over h, h/2, h/4 (Romberg), its
    step made finer until the extrapolation's error estimate meets rtol."""

    implicit = True
    order = 6

    def refuse(self, model: Model) -> str | None:
        """No ground motion (hysteretic springs, contacts and stops are refused before, with the methods that take
        them)."""
        if model.ground is not None:
            return "'sparse_newmark' does not take a ground motion; try 'auto'"
        return None

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        """Romberg's table of three runs, repeated at finer steps until its estimate meets the tolerances."""
        start = time.perf_counter()
        march = _March(model, grid, tol)
        span = float(grid[-1] - grid[0]) if len(grid) > 1 else 0.0
        spacing = span / max(len(grid) - 1, 1)
        # the coarsest step resolves the highest mode to h w <= 2 (the rule's error expansion is asymptotic in it),
        # or is the requested dt; the output spacing at most
        wished = tol.dt or (2.0 / model.omega_max if model.omega_max > 0 else spacing)
        divisions = max(1, math.ceil(spacing / wished * (1 - 1e-12))) if spacing > 0 else 1
        max_steps = tol.max_steps or MAX_STEPS
        passes, failure = 0, None
        while True:
            passes += 1
            try:
                x, v, estimate, extremes = march.extrapolated(divisions)
                peak_x, peak_v = (max(high, -low) for low, high in extremes)
            except NewtonFailed as stop:
                failure = stop
                break
            excess = max(estimate[0] / (tol.rtol * peak_x + tol.atol), estimate[1] / (tol.rtol * peak_v + tol.atol))
            finer = math.ceil(divisions * STEP_SAFETY * excess ** 0.25) if excess > 1 else divisions
            # twice the divisions where its one new run (the others kept) costs no more than a fresh pass at finer
            if LEVELS[-1] * 2 * divisions <= sum(LEVELS) * finer:
                finer = max(finer, 2 * divisions)
            if excess <= 1 or not math.isfinite(excess) or march.steps_per_pass(finer) > max_steps:
                break
            divisions = max(finer, divisions + 1)
            del x, v  # the next pass's runs take their place
        march.kept.clear()
        n = model.n
        if failure is not None:
            from smdcli.kernels.banded import NEWTON_ITERATIONS

            x = v = np.full((len(grid), n), np.nan)
            stated, met = math.nan, False
            message = (f"failed at t = {failure.t:.6g} s: Newton did not converge in {NEWTON_ITERATIONS} iterations "
                       "on a step's nonlinear equation")
        else:
            stated = max(estimate[0] / peak_x if peak_x > 0 else 0.0, estimate[1] / peak_v if peak_v > 0 else 0.0)
            met = excess <= 1
            message = "ok" if met else (f"the error estimate {stated:.3g} of the peak is above the tolerance; a finer "
                                        f"step would take more than {max_steps} steps")
        stats = SolverStats(
            method=self.name, requested_method=self.name, reason="", rtol=tol.rtol, atol=tol.atol,
            dt=spacing / divisions / LEVELS[-1], wall_time_s=time.perf_counter() - start, success=met,
            message=message, steps_accepted=march.steps, steps_rejected=0, nfev=march.evaluations, njev=march.tangents,
            nlu=march.factorizations, stated_accuracy=stated)
        notes = (f"sparse Newmark: steps of {spacing / divisions:.4g}, /2 and /4 s extrapolated (Romberg) in "
                 f"{passes} pass(es); estimated error {stated:.3g} of the peak",) if met else ()
        # past the step budget, the best it allows is still returned, flagged failed
        t_failed = None if met else failure.t if failure is not None else float(grid[-1])
        found = ((x, extremes[0]), (v, extremes[1])) if met else ()  # found as the table was combined: no pass more
        return make_result(model, grid, x, v, stats, t_failed=t_failed, notes=notes, found_extremes=found)


class _March:
    """The three Newmark runs of one step size, the factorizations they share across passes, and their counts."""

    def __init__(self, model: Model, grid: np.ndarray, tol: Tolerances):
        self.model = model
        self.grid = np.asarray(grid, dtype=float)
        edges = cuts(model, grid, tol.breakpoints)
        # nodes: output points and discontinuities; a step never crosses one
        self.nodes = np.unique(np.concatenate([self.grid, edges]))
        self.output = np.searchsorted(self.nodes, self.grid)
        self.edges = edges[1:-1]
        from scipy.sparse import csr_matrix

        self.M, self.C, self.K = (csr_matrix(A) for A in (model.M, model.C, model.K))
        self.mass = self.M.diagonal() if self.M.nnz == np.count_nonzero(self.M.diagonal()) else None
        self.lu: dict[float, object] = {}
        self.kept: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # runs by divisions, for the next pass
        self.known_steps: set[float] = set()  # the step sizes used so far: a rounding of one is the same
        self.lock = threading.Lock()  # the levels run on threads: their counts and known steps
        self.steps = self.evaluations = self.tangents = self.factorizations = 0
        self.band = _Band.of(model, self.M, self.C, self.K) if self.mass is not None else None

    def steps_per_pass(self, divisions: int) -> int:
        """Steps of the three runs at this many divisions of each interval between nodes."""
        return (len(self.nodes) - 1) * divisions * sum(LEVELS)

    def extrapolated(self, divisions: int) -> tuple[np.ndarray, np.ndarray, tuple[float, float], tuple]:
        """(x, v) on the output grid from Romberg's table of three runs, the estimated errors of x and v, and their
        extremes ((min, max) each). The runs at 2 and 4 divisions are kept: a pass at twice the divisions takes them
        as its coarser two."""
        (x, v), (x2, v2), (x3, v3) = self._levels(divisions)
        self.kept = {divisions * LEVELS[1]: (x2, v2), divisions * LEVELS[2]: (x3, v3)}
        estimate, low, high = [0.0, 0.0], [math.inf, math.inf], [-math.inf, -math.inf]
        block = max(1, ROMBERG_VALUES // max(x.shape[1], 1))
        for start in range(0, len(x), block):  # by rows: the table's temporaries stay in cache, the runs untouched
            rows = slice(start, start + block)
            for which, (coarse, middle, fine) in enumerate(((x, x2, x3), (v, v2, v3))):
                t22 = (coarse[rows] - middle[rows]) * (-1.0 / 3.0) + middle[rows]
                t32 = (middle[rows] - fine[rows]) * (-1.0 / 3.0) + fine[rows]
                t22 -= t32  # T33 = T32 - (T22 - T32) / 15; |T33 - T32| = |T22 - T32| / 15
                estimate[which] = max(estimate[which], float(np.abs(t22).max(initial=0.0)) / 15.0)
                t22 *= -1.0 / 15.0
                t22 += t32
                coarse[rows] = t22
                low[which] = min(low[which], float(t22.min()))
                high[which] = max(high[which], float(t22.max()))
        return x, v, (estimate[0], estimate[1]), ((low[0], high[0]), (low[1], high[1]))

    def _levels(self, divisions: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """The runs at each of LEVELS times `divisions` (those kept from the last pass taken as they are): on
        threads where compiled (the kernel holds no lock; on two cores the three take the time of the finest), else
        one after another."""
        wanted = [divisions * level for level in LEVELS]
        runs = {d: self.kept.pop(d) for d in wanted if d in self.kept}
        self.kept.clear()
        missing = [d for d in wanted[::-1] if d not in runs]  # the finest first: it takes longest
        if self.band is None:
            runs.update((d, self.run(d)) for d in missing)
        else:
            from smdcli import interrupts

            runs.update(zip(missing, interrupts.in_threads(self.run, missing)))
        return [runs[d] for d in wanted]

    def _step(self, length: float, divisions: int) -> float:
        """length / divisions, or a step already factored within 1e-12 of it: a uniform grid's rounded spacings are
        one step, not a factorization each (the last step then lands on the node, 1e-12 of a step off)."""
        h = length / divisions
        with self.lock:
            for known in self.known_steps:
                if abs(known - h) <= 1e-12 * h:
                    return known
            self.known_steps.add(h)
        return h

    def _factor(self, h: float):
        """The LU of K + 2 C / h + 4 M / h^2, kept per step size."""
        key = float(h)
        if key not in self.lu:
            from scipy.sparse.linalg import splu

            self.factorizations += 1
            self.lu[key] = splu((self.K + (2.0 / h) * self.C + (4.0 / h ** 2) * self.M).tocsc())
        return self.lu[key]

    def _mass_times(self, q: np.ndarray) -> np.ndarray:
        return self.mass * q if self.mass is not None else self.M @ q

    def run(self, divisions: int) -> tuple[np.ndarray, np.ndarray]:
        """One Newmark run, each interval between nodes cut into `divisions` equal steps: (x, v) at the output;
        compiled on the band where the scene has one, else stepped here on the sparse LU."""
        if self.band is not None:
            ran = self._run_banded(divisions)
            if ran is not None:
                return ran
            self.band = None  # K_eff not definite (a negative spring): the LU takes any
        return self._run_sparse(divisions)

    def _run_banded(self, divisions: int) -> tuple[np.ndarray, np.ndarray] | None:
        from smdcli.kernels import banded
        from smdcli.solvers.integrators.compiled import warm

        warm("banded")
        model, band, nodes = self.model, self.band, self.nodes
        lengths = np.diff(nodes)
        steps = np.array([self._step(length, divisions) for length in lengths])
        known, factor_of = np.unique(steps, return_inverse=True)
        effective = np.stack([band.stiffness + (2.0 / h) * band.damping + (4.0 / h ** 2) * band.mass_padded
                              for h in known])
        factors = effective.copy()
        for factor in factors:
            if not banded.cholesky(factor):
                return None
        signals = len(model.signals)
        intervals = len(nodes) - 1
        restart = np.zeros(intervals, dtype=np.bool_)
        restart[0] = True
        restart[np.isin(nodes[:-1], self.edges)] = True
        u_start = model.forces(nodes[:-1]).reshape(intervals, signals)
        times = nodes[:-1, None] + steps[:, None] * np.arange(1, divisions + 1)[None, :]
        times[:, -1] = nodes[1:]
        u_steps = model.forces(times).reshape(intervals, divisions, signals)
        for i in np.flatnonzero(np.isin(nodes[1:], self.edges)):  # a discontinuity ends it: its left limit
            u_steps[i, -1] = [s.value_left(float(nodes[i + 1])) for s in model.signals]
        forcing = (model.B if signals else np.zeros((model.n, 0)))[band.order]
        slot = np.full(len(nodes), -1, dtype=np.int64)
        slot[self.output] = np.arange(len(self.grid))
        x_out = np.empty((len(self.grid), model.n))
        v_out = np.empty((len(self.grid), model.n))
        x = np.array(model.x0, dtype=float)[band.order]
        v = np.array(model.v0, dtype=float)[band.order]
        counts, failed_at = np.zeros(3, dtype=np.int64), np.zeros(1)
        status = banded.march(band.mass, band.damping, band.stiffness, effective, factors, known, factor_of,
                              divisions, np.asarray(nodes, dtype=float), restart, u_start, u_steps, forcing,
                              *band.nonlinear, band.order, slot, x, v, x_out, v_out, counts, failed_at)
        with self.lock:  # the levels run on threads
            self.steps += int(counts[banded.STEPS])
            self.evaluations += int(counts[banded.EVALUATIONS])
            self.tangents += int(counts[banded.TANGENTS])
            self.factorizations += int(counts[banded.TANGENTS]) + len(known)
        if status == banded.NEWTON_FAILED:
            raise NewtonFailed(float(failed_at[0]))
        if status == banded.NOT_DEFINITE:
            return None
        return x_out, v_out

    def _run_sparse(self, divisions: int) -> tuple[np.ndarray, np.ndarray]:
        model = self.model
        n = model.n
        x_out = np.empty((len(self.grid), n))
        v_out = np.empty((len(self.grid), n))
        x = np.array(model.x0, dtype=float)
        v = np.array(model.v0, dtype=float)
        out_index = dict(zip(self.output.tolist(), range(len(self.grid))))
        nonlinear = not model.is_linear
        nodes = self.nodes
        B = model.B if model.is_forced else None
        a = None
        for i in range(len(nodes)):
            if i in out_index:
                x_out[out_index[i]] = x
                v_out[out_index[i]] = v
            if i == len(nodes) - 1:
                break
            ta, tb = float(nodes[i]), float(nodes[i + 1])
            h = self._step(tb - ta, divisions)
            times = ta + h * np.arange(1, divisions + 1)
            times[-1] = tb
            forces = np.zeros((divisions, n))
            if B is not None:
                values = model.forces(times)
                if tb in self.edges:  # a discontinuity ends this interval: its left limit
                    values[-1] = [s.value_left(tb) for s in model.signals]
                forces = values @ B.T
            if a is None or ta in self.edges:  # from equilibrium: at the start, and past a force's jump
                f0 = (model.forces(ta) @ B.T) if B is not None else np.zeros(n)
                a = self._acceleration(x, v, f0)
            lu = self._factor(h)
            for k in range(divisions):  # the increment d = x1 - x0, as the compiled march (banded.py) says why
                rhs = forces[k] - self.K @ x + self.C @ v + self._mass_times((4.0 / h) * v + a)
                d = lu.solve(rhs)
                if nonlinear:
                    d = self._newton(d, x, v, rhs, h, lu, float(times[k]))
                x = x + d
                v = (2.0 / h) * d - v
                a = self._acceleration(x, v, forces[k])
            self.steps += divisions
        return x_out, v_out

    def _acceleration(self, x: np.ndarray, v: np.ndarray, f: np.ndarray) -> np.ndarray:
        """M^-1 (F - C v - K x - f_nl): equilibrium."""
        self.evaluations += 1
        return self.model.acceleration(x[None], v[None], f[None])[0]

    def _newton(self, d, x, v, rhs, h: float, lu, t: float) -> np.ndarray:
        """Solve K_eff d + f_nl(x + d, 2 d / h - v) = rhs as the compiled march does (kernels/banded.py: its
        iteration limit, slow contraction and tolerance), on the sparse LU."""
        from scipy.sparse import csc_matrix
        from scipy.sparse.linalg import splu

        from smdcli.kernels.banded import NEWTON_ITERATIONS, NEWTON_SLOW, NEWTON_TOL

        model = self.model
        scale = max(float(np.abs(d).max(initial=0.0)) + float(np.abs(x).max(initial=0.0)), 1e-300)
        previous = math.inf
        for _ in range(NEWTON_ITERATIONS):
            vel = (2.0 / h) * d - v
            residual = rhs - model.nonlinear_force(x + d, vel) - self._effective_times(d, h)
            self.evaluations += 1
            delta = lu.solve(residual)
            d = d + delta
            size = float(np.abs(delta).max(initial=0.0))
            if size <= NEWTON_TOL * scale:
                return d
            if size > NEWTON_SLOW * previous:  # slow: Newton proper, on the tangent here
                Kt, Ct = model.tangent(x + d, (2.0 / h) * d - v)
                lu = splu(csc_matrix(Kt + (2.0 / h) * Ct + (4.0 / h ** 2) * self.M))
                self.tangents += 1
                self.factorizations += 1
            previous = size
        raise NewtonFailed(t)

    def _effective_times(self, y: np.ndarray, h: float) -> np.ndarray:
        return self.K @ y + (2.0 / h) * (self.C @ y) + (4.0 / h ** 2) * self._mass_times(y)


BAND_ENTRIES = 2e8  # the most band entries (n (w + 1)) per matrix held for the compiled path; wider: the LU


class _Band:
    """A sparse scene in banded form: its DOFs reordered by reverse Cuthill-McKee, M, C and K as lower bands
    (band[d, j] = A[j + d, j]), and its cubic springs and quadratic dampers as node pairs in that order."""

    def __init__(self, order, mass, damping, stiffness, nonlinear):
        self.order, self.mass, self.damping, self.stiffness, self.nonlinear = order, mass, damping, stiffness, \
            nonlinear
        self.mass_padded = np.zeros_like(stiffness)
        self.mass_padded[0] = mass[0]

    @classmethod
    def of(cls, model: Model, M, C, K) -> _Band | None:
        """The band of a scene with a diagonal M, or None where it is too wide to hold."""
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        pairs = [inc for inc in (model.cubic, model.quadratic) if inc is not None]
        pattern = abs(K) + abs(C) + abs(M)
        for inc in pairs:
            D = csr_matrix(inc.D)
            pattern = pattern + abs(D.T) @ abs(D)
        order = np.asarray(reverse_cuthill_mckee(pattern.tocsr(), symmetric_mode=True), dtype=np.int64)
        position = np.empty_like(order)
        position[order] = np.arange(len(order))
        reordered = pattern.tocoo()
        width = int(np.abs(position[reordered.row] - position[reordered.col]).max(initial=0))
        if model.n * (width + 1) > BAND_ENTRIES:
            return None

        def band(A, w):
            A = A.tocoo()
            r, c = position[A.row], position[A.col]
            lower = r >= c
            out = np.zeros((w + 1, model.n))
            np.add.at(out, (r[lower] - c[lower], c[lower]), A.data[lower])
            return out

        def ends(inc):
            if inc is None:
                return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
            nodes = np.array([[position[np.argmax(row > 0)] if (row > 0).any() else -1,
                               position[np.argmax(row < 0)] if (row < 0).any() else -1] for row in inc.D],
                             dtype=np.int64)
            return nodes, np.asarray(inc.coef, dtype=float)

        return cls(order, band(M, 0), band(C, width), band(K, width), (*ends(model.cubic), *ends(model.quadratic)))
