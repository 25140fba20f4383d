"""Sensitivities of a smooth nonlinear scene (cubic springs, quadratic dampers, Bouc-Wen springs, regularized
friction): the forward sensitivity equations s' = J(t, y) s + df/dp integrated beside the state y = [x, v, q] (q the
laws' internal variables), the error controlled on state and sensitivities together.

By the compiled kernel (smdcli.kernels.sensitivity: DOP853, restarted at the forces' discontinuities, every kink of
a law landed on: a step ends just past it, on the branch of J it started on; where Hairer's test finds the scene
stiff, kernels.implicit_sensitivity's Radau IIA from the start); a stencil model that moves M enters
through M^-1 M_j, so that its forces are combined, not its accelerations. In Python by scipy's DOP853, restarted at
the forces' discontinuities and wherever a law's right-hand side has a kink (a Bouc-Wen rate or z changing sign):
the tests' second way.

J is analytic: the model's tangent for cubic springs and quadratic dampers, each law's smooth_jacobian for its
tension and internal rates. df/dp is the right-hand side of the models at the parameter's stencil points
(model_derivative.py) at the same state, combined by the stencil's weights: exact for a parameter that enters
affinely (a stiffness, a cubic coefficient, a damper, a Bouc-Wen k), the stencil's own error otherwise (n, beta).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.analysis.signal_derivative import combined
from smdcli.elements.base import KINK
from smdcli.errors import SolverFailed
from smdcli.model import Model
from smdcli.model.nonsmooth import whole_tension

# what smd sensitivity answers, as its refusals name it (here and event_sensitivity's)
ANSWERED = ("linear scenes; elastoplastic, bilinear, Clough and Iwan springs, Coulomb friction and stops; cubic "
            "springs, quadratic dampers, Bouc-Wen springs and regularized friction; Stribeck friction, and yielding "
            "springs, friction or stops beside those smooth terms")
RTOL = 1e-9  # smd sensitivity's default for smooth nonlinear scenes (a scenario's tighter rtol applies)
COMPILED = True  # the compiled kernel where it takes the scene; the Python integration (the tests' second way) else
COMPILED_METHOD = ("forward sensitivity equations s' = J s + df/dp integrated beside the state by compiled {} "
                   "(error controlled on both, restarted at force discontinuities, every output time landed on), J "
                   "analytic, df/dp from the model at the parameter's stencil points")
KERNELS = ("DOP853", "Radau IIA 5 (the scene stiff by DOP853's test; S by its collocation formula differentiated)")
PYTHON_METHOD = ("forward sensitivity equations s' = J s + df/dp integrated beside the state by DOP853 (error "
                 "controlled on both, restarted at force discontinuities and at the laws' kinks), J analytic, df/dp "
                 "from the model at the parameter's stencil points, in Python")


def smooth_refusal(model: Model) -> str | None:
    """Why the smooth sensitivity equations cannot take the scene, or None."""
    for element in model.nonsmooth:
        law = element.law
        state = law.start(0.0, 0.0)
        piece = law.piece(state)
        if law.piecewise_linear or piece.held or any(g.kind != KINK for g in piece.guards) or \
                law.smooth_jacobian(state, 0.0, 0.0) is None:
            return (f"{element.path} ({getattr(law, 'law_name', law.name)}) changes mode at events beside smooth "
                    f"nonlinear terms: sensitivities of such a mix are not yet built (built: {ANSWERED})")
    return None


class _Flow:
    """The right-hand side of one model (its state y = [x, v, q]) and, for the nominal one, its Jacobian. Each smooth
    law stays in the mode it starts in (its only one: smooth_refusal), so its piece is taken once."""

    def __init__(self, model: Model):
        self.model = model = model.dense()
        self.n = n = model.n
        self.elements = model.nonsmooth
        self.R = np.array([e.row for e in self.elements], dtype=float).reshape(len(self.elements), n)
        self.belts = np.array([e.belt for e in self.elements], dtype=float)
        d0, rate0 = self.R @ model.x0, self.R @ model.v0 + self.belts
        self.states = [e.law.start(float(d), float(r)) for e, d, r in zip(self.elements, d0, rate0)]
        self.pieces = [e.law.piece(state) for e, state in zip(self.elements, self.states)]
        self.slices, start = [], 2 * n
        for element in self.elements:
            self.slices.append(slice(start, start + len(element.law.ode_states)))
            start += len(element.law.ode_states)
        self.q = start - 2 * n
        self.Kt, self.Ct, self.g = model.K.copy(), model.C.copy(), np.zeros(n)
        for row, piece, belt in zip(self.R, self.pieces, self.belts):  # a mode's linear part, as Scene assembles it
            self.Kt += piece.stiffness * np.outer(row, row)
            self.Ct += piece.damping * np.outer(row, row)
            self.g -= (piece.constant + piece.damping * belt) * row  # a viscous part acts on d' = R v + belt
        self.smooth = model.cubic is not None or model.quadratic is not None

    def initial(self) -> np.ndarray:
        y = [self.model.x0, self.model.v0]
        y += [np.array([s.internal[name] for name in e.law.ode_states], dtype=float)
              for e, s in zip(self.elements, self.states)]
        return np.concatenate(y).astype(float)

    def _live(self, e: int, y: np.ndarray):
        """Element e's state with its internal variables read from y."""
        from smdcli.elements import State

        state, names = self.states[e], self.elements[e].law.ode_states
        return State(state.mode, {**state.internal, **dict(zip(names, y[self.slices[e]]))}) if names else state

    def f(self, t: float, y: np.ndarray) -> np.ndarray:
        """y' at (t, y)."""
        n, model = self.n, self.model
        x, v = y[:n], y[n:2 * n]
        F = self.g - self.Kt @ x - self.Ct @ v
        if model.signals:
            F = F + model.B @ model.forces(t)
        if self.smooth:
            F = F - model.nonlinear_force(x, v)
        out = np.empty(len(y))
        out[:n] = v
        if len(self.elements):
            d, rate = self.R @ x, self.R @ v + self.belts
            for e, (element, piece) in enumerate(zip(self.elements, self.pieces)):
                state = self._live(e, y)
                if piece.nonlinear is not None:
                    F = F - piece.nonlinear(d[e], rate[e], state.internal) * self.R[e]
                if self.slices[e].stop > self.slices[e].start:
                    out[self.slices[e]] = element.law.ode(state, d[e], rate[e])
        out[n:2 * n] = model.Minv @ F
        return out

    def tensions(self, y: np.ndarray) -> np.ndarray:
        """Each element's whole tension (N, E) at the states y (N, s): its piece's k d + c d' + constant and its
        smooth term (a Bouc-Wen spring's (1 - alpha) k z), as f applies them, and the stiffness kept in K."""
        n = self.n
        d, rate = y[:, :n] @ self.R.T, y[:, n:2 * n] @ self.R.T + self.belts
        out = np.empty_like(d)
        for e, piece in enumerate(self.pieces):
            out[:, e] = piece.stiffness * d[:, e] + piece.damping * rate[:, e] + piece.constant
            if piece.nonlinear is not None:
                out[:, e] += [piece.nonlinear(d[k, e], rate[k, e], self._live(e, row).internal)
                              for k, row in enumerate(y)]
        return whole_tension(self.elements, out, d)

    def jacobian(self, t: float, y: np.ndarray) -> np.ndarray:
        """df/dy at (t, y), analytic."""
        n, model = self.n, self.model
        size = 2 * n + self.q
        J = np.zeros((size, size))
        J[:n, n:2 * n] = np.eye(n)
        x, v = y[:n], y[n:2 * n]
        Kt, Ct = self.Kt, self.Ct
        if self.smooth:
            K_nl, C_nl = model.tangent(x, v)
            Kt, Ct = Kt + K_nl - model.K, Ct + C_nl - model.C
        Minv = model.Minv
        J[n:2 * n, :n], J[n:2 * n, n:2 * n] = -Minv @ Kt, -Minv @ Ct
        if len(self.elements):
            d, rate = self.R @ x, self.R @ v + self.belts
            for e, (element, part) in enumerate(zip(self.elements, self.slices)):
                tension, rates = element.law.smooth_jacobian(self._live(e, y), float(d[e]), float(rate[e]))
                row = self.R[e]
                pushed = -Minv @ row  # a tension T on the element: M x'' gets -R_e T
                J[n:2 * n, :n] += np.outer(pushed, tension[0] * row)
                J[n:2 * n, n:2 * n] += np.outer(pushed, tension[1] * row)
                J[n:2 * n, part] += np.outer(pushed, tension[2:])
                for index, derivative in zip(range(part.start, part.stop), rates):
                    J[index, :n] += derivative[0] * row
                    J[index, n:2 * n] += derivative[1] * row
                    J[index, part] += derivative[2:]
        return J

    def kink_rows(self) -> list[tuple[np.ndarray, float]]:
        """Each law's kink quantities (an element's rate, an internal variable) as (row over y, constant)."""
        out, n, size = [], self.n, 2 * self.n + self.q
        for e, (element, piece, part) in enumerate(zip(self.elements, self.pieces, self.slices)):
            names = element.law.ode_states
            for key in dict.fromkeys(guard.quantity for guard in piece.guards):
                row = np.zeros(size)
                if key == "rate":
                    row[n:2 * n] = self.R[e]
                    out.append((row, float(self.belts[e])))
                elif key.startswith("internal:"):
                    row[part.start + names.index(key.split(":", 1)[1])] = 1.0
                    out.append((row, 0.0))
        return out


def smooth_tensions(model: Model, derivatives: list, scales: np.ndarray, y: np.ndarray,
                    S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each nonsmooth element's tension (N, E) at a smooth run's states y (N, s) and its scaled derivatives
    (N, P, E) from their sensitivities S (N, s, P): the law's slopes in d, d' and its internal variables times theirs,
    plus the stencil's partial derivative at the state."""
    flow = _Flow(model)
    n, tension = model.n, flow.tensions(y)
    derived = np.empty((len(y), len(derivatives), len(flow.elements)))
    for i, (d, scale) in enumerate(zip(derivatives, scales)):
        derived[:, i] = combined(d.weights * scale, [tension if m is model else _Flow(m).tensions(y) for m in d.models])
    for e, (element, piece, part) in enumerate(zip(flow.elements, flow.pieces, flow.slices)):
        row = flow.R[e]
        slopes = np.array([element.law.smooth_jacobian(flow._live(e, state), float(state[:n] @ row),
                                                       float(state[n:2 * n] @ row + flow.belts[e]))[0]
                           for state in y]).reshape(len(y), -1)
        slopes[:, 0] += piece.stiffness + element.law.linear_stiffness
        slopes[:, 1] += piece.damping
        moved = np.concatenate([np.einsum("j,kjp->kp", row, S[:, :n])[:, None],
                                np.einsum("j,kjp->kp", row, S[:, n:2 * n])[:, None], S[:, part]], axis=1)
        derived[:, :, e] += np.einsum("kq,kqp->kp", slopes, moved)
    return tension, derived


def smooth_sensitivities(model: Model, derivatives: list, scales: np.ndarray, grid: np.ndarray, rtol: float,
                         advance=None, start: tuple[np.ndarray, np.ndarray] | None = None):
    """(y, dy/dp * scale, y', dy'/dp * scale) on the grid: (N, s), (N, s, P), (N, s), (N, s, P), for a scene
    smooth_refusal takes, and rates_at(t, left=False) -> (y', dy'/dp * scale) at any time on the integrator's dense
    output (each piece's own: a kink or a force's break ends one; left: the piece that ends at t); advance(count) is
    called as output times are filled (a progress bar's). start: (y, S) at the grid's first time, where not the
    scene's initial state (a piece after the ground's jump); the ground's jumps: smooth_jumps.py."""
    from scipy.integrate import solve_ivp

    if model.jumps:
        from smdcli.analysis.smooth_jumps import across_ground_jumps

        return across_ground_jumps(model, derivatives, scales, grid, rtol, advance, smooth_sensitivities)
    flow = _Flow(model)
    points = [[flow if m is model else _Flow(m) for m in d.models] for d in derivatives]  # an affine one's: base, other
    weights = [d.weights * s for d, s in zip(derivatives, scales)]
    size, P = 2 * model.n + flow.q, len(derivatives)
    y0 = flow.initial() if start is None else start[0]
    s0 = (np.stack([combined(ws, [f.initial() for f in fs]) for ws, fs in zip(weights, points)], axis=1)
          if P else np.zeros((size, 0))) if start is None else start[1]
    n = model.n
    masses = [combined(ws, [f.model.M for f in fs]) for ws, fs in zip(weights, points)]  # dM/dp (scaled)

    def parameter_rates(t, y):
        """df/dp at (t, y): the stencil's combination of each model's forces M x'' (affine where p is) and
        internal rates, the accelerations then M^-1 (dF/dp - dM/dp x'')."""
        rates = flow.f(t, y)
        columns = []
        for ws, fs, dM in zip(weights, points, masses):
            values = [rates if f is flow else f.f(t, y) for f in fs]  # the scene's own rates once, not per parameter
            forces = combined(ws, [f.model.M @ v[n:2 * n] for f, v in zip(fs, values)])
            column = combined(ws, values)
            column[:n] = 0.0
            column[n:2 * n] = flow.model.Minv @ (forces - dM @ rates[n:2 * n])
            columns.append(column)
        return np.stack(columns, axis=1)

    def rhs(t, Y):
        y, S = Y[:size], Y[size:].reshape(size, P)
        return np.concatenate([flow.f(t, y), (flow.jacobian(t, y) @ S + parameter_rates(t, y)).ravel()])

    cuts = np.concatenate([[grid[0]], model.breakpoints(float(grid[0]), float(grid[-1])), [grid[-1]]])
    if COMPILED:
        y, S, rates, d_rates, implicit = compiled_sensitivities(flow, points, weights, y0, s0, grid, cuts, rtol)
        if advance is not None:
            advance(len(grid))
        return (y, S, rates, d_rates, _resumed(grid, y, S, rhs, rtol, flow, parameter_rates, cuts),
                COMPILED_METHOD.format(KERNELS[implicit]))
    # a first pass of the state alone sets the absolute tolerances: rtol of each block's peak, a thousandth of it
    peak = np.abs(solve_ivp(flow.f, (grid[0], grid[-1]), y0, method="DOP853", rtol=1e-6, atol=1e-12,
                            t_eval=grid).y).max(axis=1)
    atol = absolute_tolerances(peak, P, rtol)
    kinks = flow.kink_rows()
    Y = np.empty((len(grid), size * (1 + P)))
    state = np.concatenate([y0, s0.ravel()])
    filled = 0
    pieces = []  # (start, end, dense output) of each run
    for ta, tb in zip(cuts[:-1], cuts[1:]):
        t, fired = float(ta), None
        while t < tb:
            wanted = grid[(grid >= t) & (grid <= tb)]
            if filled and wanted.size and wanted[0] <= grid[filled - 1]:
                wanted = wanted[1:]  # the point a restart stands on is filled already
            events = [_kink_event(row, c, t, state, flow, i == fired) for i, (row, c) in enumerate(kinks)]
            run = _until_kink(rhs, t, float(tb), state, rtol, atol, wanted, events)
            if run.status < 0:
                raise SolverFailed(f"{model.source}: the sensitivity equations failed at t = {run.t[-1] if len(run.t) else t:.6g}"
                                   f" s: {run.message}")
            end = float(run.t_events[next(i for i, e in enumerate(run.t_events) if len(e))][0]) \
                if run.status == 1 else float(tb)
            pieces.append((t, end, run.sol))
            if len(run.t):
                Y[filled:filled + len(run.t)] = np.asarray(run.y).T
                filled += len(run.t)
                if advance is not None:
                    advance(len(run.t))
            if run.status == 1:  # a kink: restart there
                fired = next(i for i, e in enumerate(run.t_events) if len(e))
                t, state = float(run.t_events[fired][0]), run.y_events[fired][0]
            else:
                t, state = float(tb), run.sol(float(tb))
    if filled != len(grid):
        raise SolverFailed(f"{model.source}: the sensitivity equations filled {filled} of {len(grid)} output times")
    y = Y[:, :size]
    S = Y[:, size:].reshape(len(grid), size, P)
    rates = np.array([flow.f(t, row) for t, row in zip(grid, y)])
    d_rates = np.array([flow.jacobian(t, row) @ s + parameter_rates(t, row) for t, row, s in zip(grid, y, S)])
    starts = np.array([a for a, _, _ in pieces])

    def rates_at(t: float, left: bool = False) -> tuple[np.ndarray, np.ndarray]:
        _, _, sol = pieces[max(int(np.searchsorted(starts, t, side="left" if left else "right")) - 1, 0)]
        Y_t = sol(t)
        y_t, S_t = Y_t[:size], Y_t[size:].reshape(size, P)
        return flow.f(t, y_t), flow.jacobian(t, y_t) @ S_t + parameter_rates(t, y_t)
    rates_at.breaks = np.array([b for _, b, _ in pieces[:-1]], dtype=float)  # where one piece ends, the next starts
    return y, S, rates, d_rates, rates_at, PYTHON_METHOD


def absolute_tolerances(peak: np.ndarray, P: int, rtol: float) -> np.ndarray:
    """Absolute tolerances of [y, S] from the state's peaks: rtol of each component's peak, a thousandth of it."""
    largest = peak.max(initial=0.0)
    # a scene at rest has no scale of its own: 1e-12 of a metre (1e-12 of 1e-150 made the tolerances so small that
    # a parameter moving it from rest, x0 or a force, overflowed the kernel's error norm at its first step)
    floor = np.maximum(peak, 1e-12 * (largest if largest > 0 else 1.0))
    return np.concatenate([floor, np.repeat(floor, P)]) * rtol * 1e-3


def compiled_sensitivities(flow: _Flow, points: list, weights: list, y0: np.ndarray, s0: np.ndarray,
                           grid: np.ndarray, cuts: np.ndarray, rtol: float):
    """(y, S, y', S', implicit) on the grid by a compiled kernel (sensitivity_run's), the models at each parameter's
    stencil points handed to it as arrays; a first run of the state alone at rtol 1e-6 sets the tolerances, and
    whether the scene is stiff (implicit: Radau's kernel)."""
    from smdcli.solvers.sensitivity_run import run_sensitivities

    base = _arrays(flow)
    P, s = len(points), len(y0)
    extra = base.ns_acc  # the energy terms: nothing here reads them
    stencil = [(p, w, _arrays(f), mass_ratio(flow.model, f.model))
               for p, (ws, fs) in enumerate(zip(weights, points)) for w, f in zip(ws, fs)
               if f is not flow]  # the scene's own point adds f - f: nothing
    state0 = np.concatenate([y0, np.zeros(extra)])
    alone, _, implicit = run_sensitivities(base, [], state0, grid, cuts, 1e-6,
                                           np.concatenate([np.full(s, 1e-12), np.full(extra, np.inf)]),
                                           flow.model.source)
    return grouped_runs(base, stencil, state0, s0, grid, cuts, rtol,
                        absolute_tolerances(np.abs(alone[:, :s]).max(axis=0), P, rtol), flow.model.source, implicit)


def mass_ratio(model: Model, other: Model) -> np.ndarray | None:
    """M^-1 M_j of a stencil point's model (its forces differenced, not its accelerations), None where M is one."""
    return None if np.array_equal(other.M, model.M) else model.Minv @ other.M


def grouped_runs(base, stencil: list, state0: np.ndarray, s0: np.ndarray, grid: np.ndarray, cuts: np.ndarray,
                 rtol: float, atol: np.ndarray, source: str, implicit: bool = False):
    """(y, S, y', S', implicit) on the grid by a compiled kernel (implicit: Radau's from the start) from state0 (the
    state, then its energy terms, riding along out of the error's control) and s0 (s, P): stencil (parameter, weight,
    arrays, mass_ratio) of each model a parameter's derivative takes, run in groups of consecutive parameters as many
    as the kernel takes at a time; atol (s + s P) of [y; S]."""
    from smdcli.solvers.sensitivity_run import run_sensitivities

    (s, P), N = s0.shape, len(grid)
    extra = len(state0) - s
    S, d_S = np.empty((N, s, P)), np.empty((N, s, P))
    for group in _groups([p for p, *_ in stencil], P):  # the kernel takes STENCIL_MODELS at a time
        local = {p: i for i, p in enumerate(group)}
        models = [(local[p], w, arrays, ratio) for p, w, arrays, ratio in stencil if p in local]
        tolerance = np.concatenate([atol[:s], np.full(extra, np.inf), atol[s:].reshape(s, P)[:, group].ravel()])
        out, rates, implicit = run_sensitivities(base, models, np.concatenate([state0, s0[:, group].ravel()]), grid,
                                                 cuts, rtol, tolerance, source, implicit)
        if group[0] == 0:  # the state of the first run (the others' differ by their tolerance, not more)
            y, rate = out[:, :s], rates[:, :s]
        S[:, :, group] = out[:, s + extra:].reshape(N, s, len(group))
        d_S[:, :, group] = rates[:, s + extra:].reshape(N, s, len(group))
    return y, S, rate, d_S, implicit


def _groups(owners: list[int], P: int) -> list[list[int]]:
    """The parameters 0 .. P - 1 in runs of consecutive ones whose stencil models (owners: each model's parameter)
    number at most STENCIL_MODELS: one run for the usual few, more only for many parameters."""
    from smdcli.kernels.compiler import STENCIL_MODELS

    groups, count = [[]], 0
    for p in range(P):
        needs = owners.count(p)
        if groups[-1] and count + needs > STENCIL_MODELS:
            groups.append([])
            count = 0
        groups[-1].append(p)
        count += needs
    return groups


def _arrays(flow: _Flow):
    """The kernels' arrays of a flow's model in its one mode (smooth models' own, or a SmoothScene's mode)."""
    from smdcli.kernels.arrays import model_arrays

    if not flow.elements:
        return model_arrays(flow.model)
    from smdcli.solvers.events.compiled_modes import mode_arrays, scene_arrays
    from smdcli.solvers.events.smooth_scene import SmoothScene

    scene = SmoothScene(flow.model)
    return mode_arrays(scene_arrays(scene), scene, scene.mode(flow.states), flow.states)


def _resumed(grid: np.ndarray, y: np.ndarray, S: np.ndarray, rhs, rtol: float, flow: _Flow, parameter_rates,
             cuts: np.ndarray):
    """rates_at for a compiled run: (y', dy'/dp * scale) at any time, on the dense output of a Python DOP853 run over
    the output step that holds it, from the step's start (the state is continuous: left and right limits differ only
    in the forces, read at t). A peak's search asks for many times in one step: each step is integrated once."""
    from scipy.integrate import solve_ivp

    size, P = y.shape[1], S.shape[2]
    atol = absolute_tolerances(np.abs(y).max(axis=0), P, rtol)
    steps = {}  # output step k -> its dense output

    def rates_at(t: float, left: bool = False) -> tuple[np.ndarray, np.ndarray]:
        k = min(max(int(np.searchsorted(grid, t, side="right")) - 1, 0), len(grid) - 1)
        Y = np.concatenate([y[k], S[k].ravel()])
        if t > grid[k]:
            dense = steps.get(k)
            if dense is None or t > dense.t_max:
                end = max(float(grid[min(k + 1, len(grid) - 1)]), t)
                dense = steps[k] = solve_ivp(rhs, (float(grid[k]), end), Y, method="DOP853", rtol=rtol, atol=atol,
                                             dense_output=True).sol
            Y = dense(t)
        y_t, S_t = Y[:size], Y[size:].reshape(size, P)
        return flow.f(t, y_t), flow.jacobian(t, y_t) @ S_t + parameter_rates(t, y_t)
    rates_at.breaks = cuts[1:-1]
    return rates_at


def _until_kink(rhs, t: float, end: float, state: np.ndarray, rtol: float, atol: np.ndarray, wanted: np.ndarray,
                events: list):
    """solve_ivp's DOP853 from (t, state) to end or to the first kink, with its dense output. A kink whose root
    falls on a step's start (its value there zero to rounding) makes scipy's dense output hold that time twice and
    refuse it (ValueError: `ts` must be strictly increasing): then the kink's time is found by a run without dense
    output, and the run to it taken again without the event, its last step landing on the kink."""
    from scipy.integrate import solve_ivp

    options = dict(method="DOP853", rtol=rtol, atol=atol)
    try:
        return solve_ivp(rhs, (t, end), state, t_eval=wanted, events=events or None, dense_output=True, **options)
    except ValueError as exc:
        if "strictly increasing" not in str(exc):
            raise
    found = solve_ivp(rhs, (t, end), state, t_eval=wanted, events=events, **options)
    if found.status != 1:
        return found
    kink = float(next(e[0] for e in found.t_events if len(e)))
    run = solve_ivp(rhs, (t, kink), state, t_eval=wanted[wanted <= kink], dense_output=True, **options)
    if run.status == 0:
        run.status, run.t_events, run.y_events = 1, found.t_events, found.y_events
    return run


def _kink_event(row: np.ndarray, constant: float, start: float, state: np.ndarray, flow: _Flow, fired: bool):
    """A terminal event where a kink quantity (row y + constant) crosses zero. One at zero where the run starts (the
    kink that stopped the last run, a scene starting at rest) is read there as the sign it moves away with: else
    its zero at the start would stop the run at once, again and again."""
    size = len(row)
    y = state[:size]
    at_zero = fired or abs(row @ y + constant) <= 1e-9 * (np.abs(row) @ np.abs(y) + abs(constant)) or \
        row @ y + constant == 0.0
    leaving = float(np.sign(row @ flow.f(start, y))) or 1.0

    def value(t, Y):
        if at_zero and t <= start:
            return leaving * 1e-300
        return float(row @ Y[:size] + constant)
    value.terminal = True
    return value
