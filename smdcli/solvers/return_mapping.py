"""The Newmark family (Newmark, HHT-alpha, generalized-alpha, central difference) on scenes with hysteretic
springs, as structural codes step them: each step's Newton iteration on the new acceleration evaluates every
hysteretic spring by its return mapping from the last committed state (elastoplastic and bilinear: the trial
force projected back onto the yield surface; Bouc-Wen: z by the trapezoidal rule), with its consistent tangent in the
iteration matrix, and commits the state only when the step has converged.

    (1 - am) M a1 + am M a0 + C v_af + f_int(x_af) = F(t_af),   f_int(x_af) = (1 - af) f(x1) + af f(x0),
    x1 = x0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1),   v1 = v0 + h ((1 - gamma) a0 + gamma a1)

(force averaging of the path-dependent forces, as OpenSees' HHT). Friction and stops need events the family
cannot locate: those scenes are refused, naming the element and the methods that can.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import time

import numpy as np

from smdcli.elements import State
from smdcli.elements.bouc_wen import BoucWen
from smdcli.elements.elastoplastic import ELASTIC, MINUS, PLUS, Elastoplastic
from smdcli.model import Model
from smdcli.result import NonsmoothHistory, Result, SolverStats
from smdcli.solvers.base import MAX_STEPS, Tolerances, cuts, divergence_bound

NEWMARK_FAMILY = ("newmark", "hht", "generalized_alpha", "central_difference")
NEWTON_ITERATIONS = 50
NEWTON_TOLERANCE = 1e-12  # of the residual, relative to the forces' scale


def refusal(method: str, model: Model) -> str | None:
    """Why the Newmark family cannot take the scene (a friction contact or a stop), or None."""
    for element in model.nonsmooth:
        if not isinstance(element.law, (Elastoplastic, BoucWen)):
            what = f"a {element.law.law_name} friction contact" if element.kind == "friction" else "a stop"
            return (f"{method!r} steps hysteretic springs by their return mapping, but {element.path} is {what}, "
                    "whose stick, slip, contact and impact are events to locate: use 'exact' (piecewise-linear "
                    "scenes), 'auto', or an ODE method ('DOP853', 'Radau', 'ode45', ...)")
    return None


class _Springs:
    """The hysteretic springs' committed states, trial evaluations and commits."""

    def __init__(self, model: Model):
        self.elements = [e for e in model.nonsmooth]
        self.R = np.array([e.row for e in self.elements]).reshape(len(self.elements), model.n)
        self.committed = []
        for e in self.elements:
            if isinstance(e.law, BoucWen):
                self.committed.append({"z": e.law.z0})
            else:
                self.committed.append({"dp": 0.0})
        self.trial = [dict(c) for c in self.committed]
        self.plastic_work = 0.0

    def forces(self, x1: np.ndarray, x0: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(tensions T (E,), tangents dT/dd (E,)) of the hysteretic parts at x1, by return mapping from the
        committed state (x0 the committed deformation, h the step)."""
        d1, d0 = self.R @ x1, self.R @ x0
        T, Kt = np.zeros(len(self.elements)), np.zeros(len(self.elements))
        for e, element in enumerate(self.elements):
            law, state = element.law, self.committed[e]
            if isinstance(law, BoucWen):
                z, dz = law.z_step(state["z"], float(d0[e]), float(d1[e]), h)
                self.trial[e] = {"z": z}
                T[e], Kt[e] = (1 - law.alpha) * law.k * z, (1 - law.alpha) * law.k * dz
            else:
                T[e], Kt[e], dp = law.return_map(float(d1[e]), state["dp"])
                self.trial[e] = {"dp": dp}
        return T, Kt

    def commit(self) -> None:
        """The trial states become the committed ones; the plastic work of the step is booked."""
        for e, element in enumerate(self.elements):
            if "dp" in self.trial[e]:
                self.plastic_work += element.law.core.fy * abs(self.trial[e]["dp"] - self.committed[e]["dp"])
        self.committed = [dict(t) for t in self.trial]

    def state(self, e: int, d: float) -> State:
        """The element's State (mode and internal variables) at deformation d, committed."""
        law, c = self.elements[e].law, self.committed[e]
        if isinstance(law, BoucWen):
            return State("smooth", {"z": c["z"]})
        core = law.core
        trial = core.k * (d - c["dp"])
        mode = ELASTIC if abs(trial) < core.fy * (1 - 1e-12) else (PLUS if trial > 0 else MINUS)
        return State(mode, {"dp": c["dp"], "work": 0.0})


def solve_return_mapping(model: Model, grid: np.ndarray, tol: Tolerances, solver) -> Result:
    """The family's method `solver` (its coefficients from its options) on a scene with hysteretic springs."""
    from smdcli.solvers.base import force_function

    start = time.perf_counter()
    solver.params = dict(tol.options)
    am, af, beta, gamma = solver.coefficients()
    dt = solver.step_size(grid, tol)
    n = model.n
    springs = _Springs(model)
    M, C, K = model.M, model.C, model.K
    bound = divergence_bound(model, grid)
    max_steps = tol.max_steps or MAX_STEPS
    edges = cuts(model, grid, tol.breakpoints)
    jumps = {float(t): (dx, dv) for t, dx, dv in model.jumps}

    def internal(x1, v1, h, x0):
        """f_int without C v (K x, smooth nonlinear elements, hysteretic springs by return mapping), tangents."""
        T, Kt_h = springs.forces(x1, x0, h)
        f = K @ x1 + springs.R.T @ T
        Kt = K + (springs.R.T * Kt_h) @ springs.R
        Ct = np.zeros((n, n))
        if model.cubic is not None or model.quadratic is not None:
            f = f + model.nonlinear_force(x1, v1)
            Kn, Cn = model.tangent(x1, v1)
            Kt, Ct = Kt + Kn, Cn
        return f, Kt, Ct, T

    x, v = model.x0.astype(float).copy(), model.v0.astype(float).copy()
    u = force_function(model, float(edges[0]), float(edges[1])) if model.is_forced else None
    F0 = model.B @ u(float(grid[0])) if u is not None else np.zeros(n)
    f_prev, _, _, T = internal(x, v, 0.0, x)
    springs.commit()
    a = np.linalg.solve(M, F0 - C @ v - f_prev)
    track = _Track(springs, model, x, v, a, T, float(grid[0]), F0)
    steps = nlu = 0
    failure, t = None, float(grid[0])
    for ta, tb in zip(edges[:-1], edges[1:]):
        u = force_function(model, float(ta), float(tb)) if model.is_forced else None
        F_t = (lambda s: model.B @ u(s)) if u is not None else (lambda s: np.zeros(n))
        count = max(1, int(np.ceil((tb - ta) / dt * (1 - 1e-12))))
        h = (tb - ta) / count
        for i in range(count):
            t1 = ta + (i + 1) * h if i + 1 < count else float(tb)
            F = F_t((1 - af) * t1 + af * t)
            a1 = a.copy()
            converged = False
            for _ in range(NEWTON_ITERATIONS):
                x1 = x + h * v + h * h * ((0.5 - beta) * a + beta * a1)
                v1 = v + h * ((1 - gamma) * a + gamma * a1)
                f1, Kt, Ct, T = internal(x1, v1, h, x)
                residual = (1 - am) * M @ a1 + am * M @ a + C @ ((1 - af) * v1 + af * v) + (1 - af) * f1 + \
                    af * f_prev - F
                scale = max(float(np.abs(F).max(initial=0.0)), float(np.abs(f1).max(initial=0.0)),
                            float(np.abs(M @ a1).max(initial=0.0)), 1e-300)
                if float(np.abs(residual).max()) <= NEWTON_TOLERANCE * scale:
                    converged = True
                    break
                J = (1 - am) * M + (1 - af) * (gamma * h * (C + Ct) + beta * h * h * Kt)
                a1 = a1 - np.linalg.solve(J, residual)
                nlu += 1
            steps += 1
            if not converged:
                failure = f"Newton did not converge in {NEWTON_ITERATIONS} iterations"
            elif steps > max_steps:
                failure = f"more than {max_steps} steps"
            elif not np.isfinite(x1).all() or np.abs(x1).max() > bound:
                failure = f"the solution grew past {bound:.3g}: unstable at this step"
            if failure:
                break
            springs.commit()
            track.add(t1, x1, v1, a1, T, F_t(t1), h)
            x, v, a, t, f_prev = x1, v1, a1, t1, f1
        if failure:
            break
        if float(tb) in jumps:  # the ground's jump: the relative state jumps, the method restarts from equilibrium
            dx, dv = jumps[float(tb)]
            x, v = x + dx, v + dv
            f_prev, _, _, T = internal(x, v, 0.0, x)
            springs.commit()
            u = force_function(model, float(tb), float(tb)) if model.is_forced else None
            a = np.linalg.solve(M, (model.B @ u(float(tb)) if u is not None else 0.0) - C @ v - f_prev)
            track.restart(x, v, a, T)
    stats = SolverStats(method=solver.name, requested_method=solver.name, reason="", rtol=tol.rtol, atol=tol.atol,
                        dt=float(dt), wall_time_s=time.perf_counter() - start, success=failure is None,
                        message=("ok: hysteretic springs by return mapping with their consistent tangent"
                                 if failure is None else f"failed at t = {t:.6g} s: {failure}"),
                        steps_accepted=steps, nlu=nlu, nfev=steps)
    x_g, v_g, a_g, history = track.on(grid, model)
    if failure:
        for q in (x_g, v_g, a_g):
            q[grid > t] = np.nan
    force = model.applied_force(grid) if model.is_forced else np.zeros_like(x_g)
    return Result(time=grid, dofs=model.dofs, displacement=x_g, velocity=v_g, acceleration=a_g, force=force,
                  stats=stats, t_failed=None if failure is None else t, nonsmooth=history)


class _Track:
    """The steps' states, the springs' tensions and internal variables, and the energy, step by step."""

    def __init__(self, springs: _Springs, model: Model, x, v, a, T, t: float, F):
        self.springs, self.model = springs, model
        self.t, self.x, self.v, self.a = [t], [x.copy()], [v.copy()], [a.copy()]
        self.T, self.internal = [T.copy()], [self._internal()]
        self.work, self.dissipated, self.hysteretic = [0.0], [0.0], [0.0]
        self.loop_work = 0.0  # work done on the hysteretic parts: what they store plus what they dissipate
        self.stored0 = self._stored(x)
        self.strain = [self._strain(x)]
        self.F = F

    def _internal(self) -> list[float]:
        return [c["z"] if "z" in c else c["dp"] for c in self.springs.committed]

    def _stored(self, x) -> float:
        """What the hysteretic parts store at x, committed states."""
        d = self.springs.R @ x
        return sum(el.law.stored(self.springs.state(e, float(d[e])), float(d[e]))[1]
                   for e, el in enumerate(self.springs.elements))

    def _power(self, v) -> float:
        """What the dampers dissipate at v: C and the quadratic ones."""
        model = self.model
        power = float(v @ model.C @ v)
        if model.quadratic is not None:
            rate = model.quadratic.D @ v
            power += float((model.quadratic.coef * np.abs(rate) * rate * rate).sum())
        return power

    def add(self, t: float, x, v, a, T, F, h: float) -> None:
        """A converged step's state; the work and dissipation over it by the trapezoid rule (the method's order)."""
        R = self.springs.R
        self.work.append(self.work[-1] + 0.5 * h * (float(self.F @ self.v[-1]) + float(F @ v)))
        self.dissipated.append(self.dissipated[-1] + 0.5 * h * (self._power(self.v[-1]) + self._power(v)))
        self.loop_work += float(0.5 * (self.T[-1] + T) @ (R @ x - R @ self.x[-1]))
        self.hysteretic.append(self.loop_work - (self._stored(x) - self.stored0))
        self._append(t, x, v, a, T, F)

    def restart(self, x, v, a, T) -> None:
        """After the ground's jump: the state after it, at the same time (the grid keeps the right limit)."""
        self.loop_work -= self._stored(x) - self._stored(self.x[-1])  # the jump moves what the parts store
        self.work.append(self.work[-1] + self._mechanical(x, v) - self._mechanical(self.x[-1], self.v[-1]))
        self.dissipated.append(self.dissipated[-1])
        self.hysteretic.append(self.hysteretic[-1])
        self._append(self.t[-1], x, v, a, T, self.F)

    def _append(self, t, x, v, a, T, F) -> None:
        self.t.append(t)
        self.x.append(x.copy())
        self.v.append(v.copy())
        self.a.append(a.copy())
        self.T.append(T.copy())
        self.internal.append(self._internal())
        self.strain.append(self._strain(x))  # with the states just committed: this step's
        self.F = F

    def _mechanical(self, x, v) -> float:
        return 0.5 * float(v @ self.model.M @ v) + self._strain(x)

    def _strain(self, x) -> float:
        model = self.model
        strain = 0.5 * float(x @ model.K @ x) + self._stored(x)
        if model.cubic is not None:
            strain += float((0.25 * model.cubic.coef * (model.cubic.D @ x) ** 4).sum())
        return strain

    def on(self, grid: np.ndarray, model: Model):
        """x, v, a on the grid (cubic Hermite between steps) and the history (linear between steps)."""
        t = np.array(self.t)
        x, v, a = np.array(self.x), np.array(self.v), np.array(self.a)
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

        springs = self.springs
        names = [f"{el.path}.{name}" for el in springs.elements for name in el.law.internal_names]
        internal = linear(self.internal)
        T = linear(self.T)
        d = xg @ springs.R.T
        tension = T + d * np.array([el.law.linear_stiffness for el in springs.elements])
        kinetic = 0.5 * np.einsum("gi,ij,gj->g", vg, model.M, vg)
        strain = linear(self.strain)
        energy = {"kinetic": kinetic, "strain": strain, "contact": np.zeros(len(grid)),
                  "dissipated": linear(self.dissipated), "input": linear(self.work),
                  "hysteretic": linear(self.hysteretic), "friction": np.zeros(len(grid)),
                  "impact": np.zeros(len(grid)),
                  "quadrature": "trapezoid rule a step (the method's own order), the springs' work by their "
                                "return-mapped forces"}
        history = NonsmoothHistory(tuple(e.path for e in springs.elements), tuple(e.kind for e in springs.elements),
                                   tension, {name: internal[:, i] for i, name in enumerate(names)}, (), energy)
        return xg, vg, ag, history
