"""The Newmark family (Newmark, Hilber-alpha, generalized-alpha, central difference) on scenes with hysteretic
springs, as structural codes step them: each step's Newton iteration on the new acceleration evaluates every
hysteretic spring by its return mapping from the last committed state (elastoplastic and bilinear: the trial
force projected back onto the yield surface; Bouc-Wen: z by the trapezoidal rule), with its consistent tangent in the
iteration matrix, and commits the state only when the step has converged.

    (1 - am) M a1 + am M a0 + C v_af + f_int(x_af) = F(t_af),   f_int(x_af) = (1 - af) f(x1) + af f(x0),
    x1 = x0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1),   v1 = v0 + h ((1 - gamma) a0 + gamma a1)

(force averaging of the path-dependent forces, as OpenSees does for Hilber-alpha). The steps run in the compiled kernel
smdcli.kernels.return_mapping; this module hands the springs over and puts the steps on the output grid. At a
ground jump the method restarts from equilibrium, each spring return-mapped through the jump. Friction and stops
need events the family cannot locate: those scenes are refused, naming the element and the methods that can.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
import time

import numpy as np

from smdcli.model import Model
from smdcli.model.nonsmooth import whole_tension
from smdcli.result import NonsmoothHistory, Result, SolverStats
from smdcli.solvers.base import MAX_STEPS, Tolerances, cuts, divergence_bound, make_result



def refusal(method: str, model: Model) -> str | None:
    """Why the Newmark family cannot take the scene (a friction contact or a stop), or None."""
    for element in model.nonsmooth:
        if element.law.newmark_rows(0.0) is None:
            if element.kind == "spring":
                what = f"a {element.law.name} spring, which it has no return mapping for"
            else:
                what = (f"a {element.law.law_name} friction contact" if element.kind == "friction" else "a stop") + \
                    ", whose stick, slip, contact and impact are events to locate"
            return (f"{method!r} steps hysteretic springs by their return mapping, but {element.path} is {what}: "
                    "use 'exact' (piecewise-linear scenes), 'auto', or an ODE method ('DOP853', 'Radau', 'ode45', "
                    "...)")
    return None


def spring_table(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The hysteretic springs as the compiled kernel takes them, one row per part of a law (Law.newmark_rows): rows
    R (d = R x), law codes, parameters, the initial committed states, and each row's element."""
    rows = [(e, row) for e, element in enumerate(model.nonsmooth)
            for row in element.law.newmark_rows(float(element.row @ model.x0))]
    R = np.array([model.nonsmooth[e].row for e, _ in rows], dtype=float).reshape(len(rows), model.n)
    laws = np.array([code for _, (code, _, _) in rows], dtype=np.int64)
    par = np.zeros((len(rows), 5))
    for i, (_, (_, parameters, _)) in enumerate(rows):
        par[i, :len(parameters)] = parameters
    committed = np.array([state for _, (_, _, state) in rows], dtype=float)
    owner = np.array([e for e, _ in rows], dtype=np.int64)
    return R, laws, par, committed, owner


def solve_return_mapping(model: Model, grid: np.ndarray, tol: Tolerances, solver) -> Result:
    """The family's method `solver` (its coefficients from its options) on a scene with hysteretic springs, stepped
    by the compiled kernel (smdcli.kernels.return_mapping)."""
    from smdcli.kernels import return_mapping as kernel
    from smdcli.kernels.arrays import model_arrays
    from smdcli.kernels.rhs import work_size
    from smdcli.solvers.integrators.compiled import warm

    warm("return_mapping")
    start = time.perf_counter()
    solver.params = dict(tol.options)
    dt = solver.step_size(grid, tol)
    n = model.n
    R, laws, par, committed, owner = spring_table(model)
    bound = divergence_bound(model, grid)
    max_steps = tol.max_steps or MAX_STEPS
    jumps = {float(t): (dx, dv) for t, dx, dv in model.jumps}
    edges = cuts(model, grid, tol.breakpoints)  # and the ground's jumps, where the method restarts
    edges = np.union1d(edges, [t for t in jumps if edges[0] < t < edges[-1]])
    jump_dx, jump_dv = np.zeros((len(edges), n)), np.zeros((len(edges), n))
    for i, t in enumerate(edges[1:-1], start=1):
        if float(t) in jumps:
            jump_dx[i], jump_dv[i] = jumps[float(t)]
    steps = sum(max(1, math.ceil((tb - ta) / dt * (1 - 1e-12))) for ta, tb in zip(edges[:-1], edges[1:]))
    rows = min(steps, max_steps + 1) + len(edges)
    t_out, e_out = np.zeros(rows), np.zeros((rows, 4))
    x_out, v_out, a_out = np.zeros((rows, n)), np.zeros((rows, n)), np.zeros((rows, n))
    T_out, q_out = np.zeros((rows, len(laws))), np.zeros((rows, len(laws)))
    counts, floats = np.zeros(2, dtype=np.int64), np.zeros(1)
    arrays = model_arrays(model)
    status, written = kernel.march(
        arrays, np.ascontiguousarray(model.M, dtype=float), np.ascontiguousarray(model.C, dtype=float),
        np.ascontiguousarray(model.K, dtype=float), R, laws, par, np.array(solver.coefficients(), dtype=float),
        model.x0.astype(float).copy(), model.v0.astype(float).copy(), committed, np.asarray(edges, dtype=float),
        jump_dx, jump_dv, float(dt), int(max_steps), float(bound), t_out, x_out, v_out, a_out, T_out, q_out, e_out,
        counts, floats, np.zeros(work_size(arrays)))
    t = float(floats[kernel.T_REACHED])
    failure = {kernel.OK: None,
               kernel.NEWTON_FAILED: f"Newton did not converge in {kernel.NEWTON_ITERATIONS} iterations",
               kernel.STEP_BUDGET: f"more than {max_steps} steps",
               kernel.DIVERGED: f"the solution grew past {bound:.3g}: unstable at this step"}[status]
    stats = SolverStats(method=solver.name, requested_method=solver.name, reason="", rtol=tol.rtol, atol=tol.atol,
                        dt=float(dt), wall_time_s=time.perf_counter() - start, success=failure is None,
                        message=("ok: hysteretic springs by return mapping with their consistent tangent (compiled)"
                                 if failure is None else f"failed at t = {t:.6g} s: {failure}"),
                        steps_accepted=int(counts[kernel.STEPS]), nlu=int(counts[kernel.FACTORIZATIONS]),
                        nfev=int(counts[kernel.STEPS]))
    w = slice(0, written)
    tensions = np.zeros((written, len(model.nonsmooth)))
    np.add.at(tensions, (slice(None), owner), T_out[w])  # a law of several parts pulls with their sum
    x_g, v_g, a_g, history = on_grid(grid, model, tensions, t_out[w], x_out[w], v_out[w], a_out[w], q_out[w], e_out[w])
    if failure:
        for q in (x_g, v_g, a_g):
            q[grid > t] = np.nan
    return make_result(model, grid, x_g, v_g, stats, t_failed=None if failure is None else t, acceleration=a_g,
                       nonsmooth=history)


def on_grid(grid: np.ndarray, model: Model, T, t, x, v, a, internal, energies):
    """x, v, a on the grid (cubic Hermite between steps) and the history (linear between steps) from the steps'
    times, states, springs' tensions and internal variables, and energy terms (work, dissipated, hysteretic,
    strain)."""
    # the last state at each distinct time (a jump's right limit)
    keep = np.concatenate([t[1:] != t[:-1], [True]])
    t, x, v, a = t[keep], x[keep], v[keep], a[keep]
    index = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, len(t) - 2) if len(t) > 1 else \
        np.zeros(len(grid), dtype=int)
    if len(t) > 1:
        h = (t[index + 1] - t[index])[:, None]
        s = ((grid - t[index])[:, None] / h)
        x0, x1, v0, v1, a0, a1 = x[index], x[index + 1], v[index], v[index + 1], a[index], a[index + 1]
        h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
        xg = h00 * x0 + h10 * h * v0 + h01 * x1 + h11 * h * v1
        d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
        vg = (d00 * x0 + d01 * x1) / h + d10 * v0 + d11 * v1
        ag = a0 + s * (a1 - a0)
    else:
        xg, vg, ag = (np.repeat(q, len(grid), axis=0) for q in (x, v, a))

    def linear(values) -> np.ndarray:
        values = np.asarray(values, dtype=float)[keep]
        if values.ndim == 1:
            return np.interp(grid, t, values)
        return np.stack([np.interp(grid, t, values[:, j]) for j in range(values.shape[1])], axis=1) \
            if values.shape[1] else np.zeros((len(grid), 0))

    elements = model.nonsmooth
    names = [f"{el.path}.{name}" for el in elements for name in el.law.internal_names]
    internal = linear(internal)
    T = linear(T)
    d = xg @ np.array([e.row for e in elements], dtype=float).reshape(len(elements), model.n).T
    tension = whole_tension(elements, T, d)
    kinetic = 0.5 * np.einsum("gi,ij,gj->g", vg, model.M, vg)
    work, dissipated, hysteretic, strain = (linear(energies[:, j]) for j in range(4))
    energy = {"kinetic": kinetic, "strain": strain, "contact": np.zeros(len(grid)),
              "dissipated": dissipated, "input": work, "hysteretic": hysteretic, "friction": np.zeros(len(grid)),
              "impact": np.zeros(len(grid)),
              "quadrature": "trapezoid rule a step (the method's own order), the springs' work by their "
                            "return-mapped forces"}
    history = NonsmoothHistory(tuple(e.path for e in elements), tuple(e.kind for e in elements),
                               tension, {name: internal[:, i] for i, name in enumerate(names)}, (), energy)
    return xg, vg, ag, history
