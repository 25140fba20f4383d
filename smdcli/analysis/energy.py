"""The energy balance of a solved run, its own check of physical accuracy, and the element forces beside it.

Multiplying M x'' + C x' + K x + f_nl = F by x'^T and integrating: kinetic + strain - initial + dissipated
- input = 0, with dissipated = int x'^T C x' (+ c |d'|^3 of quadratic dampers) and input = int x'^T F. Under
support motion x is relative to the ground and F includes -M 1 a_g (the relative energy of Uang and Bertero); a
jump of the ground's displacement or velocity does the work of the jump in the state, which is booked as input.

The integrals are taken so that they add no error of their own where the run has none:
- a linear scene whose forces all have exact generators: every output step's integrals in closed form, from
  the run's state at the step's start, over the exactly propagated trajectory (Van Loan's block exponential of
  [[-A^T, Q], [0, A]] for the augmented system z' = A z and the quadratic form Q of each power, the step split
  at force discontinuities and the ground's jumps). For the exact solver the residual is rounding; for any
  other method it sums the energy each step gained or lost against the exact flow.
- otherwise (nonlinear, forces without an exact form, models too large for the block exponential), an adaptive
  method's run: 8-point Gauss-Legendre on the method's dense output, each output step split at the force
  discontinuities and the ground's jumps.
- otherwise: per output step on the quintic Hermite interpolant of the run's (x, v, a), error O(h^6): the
  linear dampers' power exactly (a Gram form of the step's ends: a dozen inner products a step, where Gauss at
  8 nodes took 8 products with C), the forces' power and quadratic dampers by 8-point Gauss-Legendre; the steps a
  force discontinuity or a ground jump interrupts are re-integrated from the run's state at their start, across
  what happens inside them.

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from smdcli.model import Model
from smdcli.model.elements import incidence_matrix
from smdcli.analysis.forces import ROWS_VALUES, element_forces
from smdcli.analysis.hermite_rule import gram_power, hermite_slopes, node_rates
from smdcli.model.sparse import cheapest, rows_times
from smdcli.result import Energy, Result, largest_energy, moving_columns

VAN_LOAN_SIZE = 400  # largest augmented state taken in closed form: two exponentials of twice this size
GAUSS_POINTS = 8
_CHUNK_VALUES = 4_000_000  # node values (steps x points x DOFs) evaluated at once by the Hermite rule
_DENSE_VALUES = 20_000_000  # node velocities (nodes x DOFs) a dense-output re-run may hold


def with_physics(model: Model, result: Result) -> Result:
    """The run with its element forces and energy balance attached (a successful run's outputs)."""
    with np.errstate(all="ignore"):  # a scene at the edge of double precision: judged by the figures, not warned
        elements = element_forces(model, result.displacement, result.velocity, result.nonsmooth)
    if result.nonsmooth is not None:  # the solver integrated the balance on its own pieces, modes known
        return result.changed(elements=elements, energy=result.nonsmooth.balance())
    return result.changed(elements=elements, energy=energy_balance(model, result, result.interpolant))


def mechanical_energy(model: Model, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic 1/2 v^T M v and strain energy per row, J: summed over the springs (1/2 k d^2 + k3 d^4 / 4) where
    the scene has elements, since x^T K x of a stiff spring between masses that move together cancels digits."""
    M = cheapest(model.M)
    D, k, k3 = _incidence(model, "spring") if model.element_form else (None, None, None)
    kinetic, strain = np.empty(len(x)), np.empty(len(x))
    rows = max(1, ROWS_VALUES // max(x.shape[-1], 1))  # temporaries of a block of rows, in cache
    for lo in range(0, len(x), rows):
        xs, vs = x[lo:lo + rows], v[lo:lo + rows]
        kinetic[lo:lo + rows] = 0.5 * (rows_times(vs, M) * vs).sum(axis=1)
        if D is not None:
            d = rows_times(xs, D.T)
            strain[lo:lo + rows] = (0.5 * k * d**2 + 0.25 * k3 * d**4 if k3.any() else 0.5 * k * d**2).sum(axis=1)
        else:
            strain[lo:lo + rows] = 0.5 * (rows_times(xs, model.sparse[1]) * xs).sum(axis=1)
    return kinetic, strain


def _incidence(model: Model, kind: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows d = x_a - x_b of the linear-law elements of a kind (CSR where that is cheaper), their coefficients, and
    k3 (0 but for cubic); kept with the (frozen) model, as its cached properties are."""
    key = f"_incidence_{kind}"
    if key not in model.__dict__:
        chosen = [e for e in model.elements if e.kind == kind and e.law != "quadratic"]
        model.__dict__[key] = (incidence_matrix(chosen, model.n), np.array([e.coef for e in chosen]),
                               np.array([e.k3 if e.law == "cubic" else 0.0 for e in chosen]))
    return model.__dict__[key]


def _dissipation(model: Model, v: np.ndarray) -> np.ndarray:
    """x'^T C x' + c |d'|^3 of quadratic dampers, per element where the scene has them, over the last axis."""
    power = sum(((L * R).sum(axis=-1) for L, R in (form(v) for form in _damper_forms(model))), np.zeros(v.shape[:-1]))
    return power if model.quadratic is None else power + _quadratic_dampers(model, v @ model.quadratic.D.T)


def _quadratic_dampers(model: Model, rates: np.ndarray) -> np.ndarray:
    """The quadratic dampers' power c |d'|^3 at their rates d' (..., dampers), summed over the last axis."""
    return (model.quadratic.coef * np.abs(rates) ** 3).sum(axis=-1)


def _input_power(model: Model, v: np.ndarray, times: np.ndarray) -> np.ndarray:
    """x'^T B u(t), the applied forces' power, at velocities v (..., n) and their times (flat, as many as v's leading
    entries)."""
    return _forces_power(model, v @ model.B, times) if model.signals else np.zeros(v.shape[:-1])


def _forces_power(model: Model, along: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Each force's value times the rate it acts on (along = x' B, (..., forces); not the n-wide force B u of every
    time), summed over the forces, at the times (flat, as many as along's leading entries)."""
    return (along * model.forces(times).reshape(along.shape)).sum(axis=-1)


def _damper_forms(model: Model, moving: np.ndarray | None = None) -> list[Callable]:
    """The linear dampers' power as the sum of <L v, R v> over forms y -> (L y, R y) of rows of states, R's weight
    symmetric (the Hermite rule's Gram form needs it): the damper rows and their coefficients and added damping, or C
    itself where the scene has no elements; kept with the (frozen) model, as _incidence is; with `moving`
    (result.moving_columns), of states held at those columns, the others 0 throughout (those not kept)."""
    if moving is None and "_damper_forms" in model.__dict__:
        return model.__dict__["_damper_forms"]
    cut = (lambda A: A) if moving is None else (  # noqa: E731 (rows and columns of the moving DOFs)
        lambda A: A[np.ix_(moving, moving)] if isinstance(A, np.ndarray) else A[moving][:, moving])
    if not model.element_form:
        C = model.sparse[0]
        symmetric_C = cut(0.5 * (C + C.T))
        forms = [lambda y: (y, rows_times(y, symmetric_C))]
    else:
        forms = []
        D, c, _ = _incidence(model, "damper")
        if moving is not None and len(c):  # the dampers that touch the moving DOFs, on their columns
            D = D[:, moving]
            touched = np.flatnonzero(np.asarray(abs(D).sum(axis=1)).ravel())
            D, c = D[touched], c[touched]
        if len(c):
            forms.append(lambda y: (lambda dy: (dy, dy * c))(rows_times(y, D.T)))
        if model.added_damping is not None:
            added = cut(0.5 * (model.added_damping + model.added_damping.T))
            forms.append(lambda y: (y, y @ added))
    if moving is None:
        model.__dict__["_damper_forms"] = forms
    return forms


def energy_balance(model: Model, result: Result, dense: Callable | None = None) -> Energy:
    """Kinetic, strain, cumulative dissipated and input energy, and the residual of their balance; dense gives the
    run's (x, v) at any sorted times where the method has a dense output."""
    with np.errstate(all="ignore"):  # a scene at the edge of double precision: judged by the figures, not warned
        return _energy_balance(model, result, dense)


def _energy_balance(model: Model, result: Result, dense) -> Energy:
    x, v = result.displacement, result.velocity
    kinetic, strain = mechanical_energy(model, x, v)
    closed = _closed_form_applies(model)
    if closed and len(result.time) >= 2:
        try:
            dissipated, work = _closed_form(model, result)
        except _Overflows:  # |A| dt past double precision (a mass of 1e-250 kg): the quadratures below instead
            closed = False
    if len(result.time) < 2:
        dissipated = work = np.zeros(len(result.time))
        quadrature = "none: a single output time"
    elif closed:
        quadrature = ("closed form per output step over the exactly propagated trajectory from the run's state "
                      "(Van Loan block exponential)")
    elif dense is not None and len(result.time) * GAUSS_POINTS * model.n <= _DENSE_VALUES:
        dissipated, work = _dense_gauss(model, result, dense)
        quadrature = (f"{GAUSS_POINTS}-point Gauss-Legendre per output step (split at force discontinuities) on the "
                      "method's dense output")
    else:
        dissipated, work = _hermite_gauss(model, result)
        quadrature = ("the quintic Hermite interpolant of the run's x, v, a per output step (error O(h^6)): the "
                      f"linear dampers' power integrated exactly on it, the rest by {GAUSS_POINTS}-point "
                      "Gauss-Legendre; steps with a force discontinuity or a ground jump re-integrated from the "
                      "run's state at their start")
    initial = kinetic[0] + strain[0] if len(kinetic) else 0.0
    residual = kinetic + strain - initial + dissipated - work
    reached = largest_energy(kinetic, strain, dissipated, work)
    worst = float(np.max(np.abs(residual), initial=0.0))
    relative = worst / reached if reached > 0 else 0.0
    return Energy(kinetic, strain, dissipated, work, residual, relative if math.isfinite(relative) else math.inf,
                  quadrature)


def _closed_form_applies(model: Model) -> bool:
    """Linear, every force with an exact generator, and an augmented state small enough for the block exponential."""
    if not model.is_linear or any(s.exo() is None for s in model.signals):
        return False
    return 2 * model.n + sum(s.exo().S.shape[0] for s in model.signals) <= VAN_LOAN_SIZE


def _power_forms(model: Model, blocks, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric Q with z^T Q z = x'^T C x' (dissipation) and = x'^T B u (input power) on the augmented state."""
    n = model.n
    dissipation = np.zeros((size, size))
    dissipation[n:2 * n, n:2 * n] = 0.5 * (model.C + model.C.T)
    power = np.zeros((size, size))
    for j, (lo, hi, signal) in enumerate(blocks):
        power[n:2 * n, lo:hi] = np.outer(model.B[:, j], signal.exo().g)
    return dissipation, 0.5 * (power + power.T)


class _Overflows(ArithmeticError):
    """The block exponential's scaling overflows double precision."""


class _StepIntegrals:
    """Phi(dt) = expm(A dt) and W(dt) = int_0^dt Phi^T Q Phi for each form Q, cached by dt."""

    def __init__(self, A: np.ndarray, forms: tuple[np.ndarray, ...]):
        self.A, self.forms, self.cache = A, forms, {}
        self.norm = float(np.abs(A).sum(axis=0).max(initial=0.0))

    def __call__(self, dt: float) -> tuple[np.ndarray, list[np.ndarray]]:
        if dt not in self.cache:
            self.cache[dt] = self._compute(dt)
        return self.cache[dt]

    def _compute(self, dt: float):
        from smdcli.solvers.exact.accurate_expm import expm_stack  # numpy only: scipy.linalg is 0.2 s of a start-up

        # Van Loan's block exponential on dt / 2^s with |A| dt / 2^s <= 1/2 (no growth of e^{-A^T t} to lose
        # digits in), then doubling: W(2t) = W(t) + Phi(t)^T W(t) Phi(t), Phi(2t) = Phi(t)^2.
        if not math.isfinite(self.norm * dt):
            raise _Overflows
        doublings = max(0, math.ceil(math.log2(max(self.norm * dt, 1e-300) / 0.5))) if dt > 0 else 0
        tau = dt / 2**doublings
        m = len(self.A)
        blocks = np.zeros((len(self.forms), 2 * m, 2 * m))
        for block, Q in zip(blocks, self.forms):
            block[:m, :m], block[:m, m:], block[m:, m:] = -self.A.T * tau, Q * tau, self.A * tau
        E = expm_stack(blocks)
        phi = E[0, m:, m:]
        W = [phi.T @ one[:m, m:] for one in E]
        for _ in range(doublings):
            W = [w + phi.T @ w @ phi for w in W]
            phi = phi @ phi
        return phi, [0.5 * (w + w.T) for w in W]


def _closed_form(model: Model, result: Result) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative dissipated and input energy by the closed-form integrals of every output step."""
    from smdcli.solvers.exact.linear import augmented

    A, blocks = augmented(model)
    size, n, grid = len(A), model.n, result.time
    dissipation, power = _power_forms(model, blocks, size)
    # In energy coordinates (modal displacements times omega, modal velocities) a mode's share of every power
    # form is bounded by its energy: a stiff mode's large entries meet its small coordinates, not cancellation.
    T = _energy_coordinates(model, size)
    Tinv = np.linalg.inv(T)
    integrals = _StepIntegrals(Tinv @ A @ T, (T.T @ dissipation @ T, T.T @ power @ T))
    N = len(grid)
    h = (grid[-1] - grid[0]) / (N - 1)
    z = np.zeros((N, size))
    z[:, :n], z[:, n:2 * n] = result.displacement, result.velocity
    # A force edge within rounding of an output point counts as on it (_events): the step from there starts
    # after the edge, so the generator's state there is read just after it (a pulse's end 0.0503 + 0.0917 lands
    # a rounding past the point 142 * 0.001, and read at the point the pulse was still on for the next step).
    after = grid.copy()
    edges = model.breakpoints(float(grid[0]), float(grid[-1]))
    if len(edges):
        k = np.clip(np.searchsorted(grid, edges), 1, len(grid) - 1)
        k = np.where(np.abs(grid[k - 1] - edges) < np.abs(grid[k] - edges), k - 1, k)  # the nearest point
        on = np.abs(grid[k] - edges) <= 1e-9 * h
        np.maximum.at(after, k[on], edges[on])
    for lo, hi, signal in blocks:
        z[:, lo:hi] = signal.exo_states(after)
    z = z @ Tinv.T
    events = _events(model, grid, h)
    regular = np.arange(N) > 0  # the steps with nothing inside them, by their ends
    regular[[k for k, t, _ in events if t is not None]] = False
    step = np.zeros((2, N))  # each step's dissipated and input energy, booked at its end
    _, (Wd, Wp) = integrals(h)
    start = z[np.flatnonzero(regular) - 1]  # each s^T W s as (s W) . s: einsum's "ki,ij,kj" took 8 ms at 30 DOFs
    step[:, regular] = [np.einsum("ki,ki->k", start @ W, start) for W in (Wd, Wp)]
    by_step: dict[int, list] = {}
    for k, t, jump in events:
        by_step.setdefault(k, []).append((t, jump))
    for k, happenings in by_step.items():
        inner = sorted((item for item in happenings if item[0] is not None), key=lambda item: item[0])
        if inner:  # propagate from the step's start across what happens inside it
            state, t = z[k - 1].copy(), float(grid[k - 1])
            for t_event, jump in inner + [(float(grid[k]), None)]:
                phi, (Wd, Wp) = integrals(t_event - t)
                step[:, k] += state @ Wd @ state, state @ Wp @ state
                state = T @ (phi @ state)
                if jump is not None:
                    step[1, k] += _jump_work(model, state, jump)
                    state[:n] += jump[0]
                    state[n:2 * n] += jump[1]
                for lo, hi, signal in blocks:
                    state[lo:hi] = signal.exo_state(t_event)
                state, t = Tinv @ state, t_event
        for t_event, jump in happenings:
            if t_event is None and jump is not None:  # a jump on the grid point: the output there is after it
                before = T @ z[k]
                before[:n] -= jump[0]
                before[n:2 * n] -= jump[1]
                step[1, k] += _jump_work(model, before, jump)
    return np.cumsum(step[0]), np.cumsum(step[1])


def _energy_coordinates(model: Model, size: int) -> np.ndarray:
    """T with z = T xi: xi holds omega q and q' of the undamped modes (x = Phi q, Phi^T M Phi = I), then the
    force generators' states unchanged; a rigid-body mode's omega is floored."""
    n = model.n
    shapes = model.modes.shapes
    omega = np.sqrt(np.maximum(((shapes.T @ model.K) * shapes.T).sum(axis=1), 0.0))
    omega = np.maximum(omega, 1e-6 * max(float(omega.max(initial=0.0)), 1.0))
    T = np.eye(size)
    T[:n, :n] = shapes / omega
    T[n:2 * n, n:2 * n] = shapes
    return T


def _jump_work(model: Model, state: np.ndarray, jump) -> float:
    """The mechanical energy a jump (dx, dv) of the state adds: the work of the ground's impulse."""
    n = model.n
    x, v = state[None, :n], state[None, n:2 * n]
    before = sum(mechanical_energy(model, x, v))
    after = sum(mechanical_energy(model, x + jump[0], v + jump[1]))
    return float(after[0] - before[0])


def _events(model: Model, grid: np.ndarray, h: float) -> list[tuple[int, float | None, tuple | None]]:
    """Force discontinuities and ground jumps as (step k, time inside step k or None on grid point k, jump or
    None for a force discontinuity)."""
    t0, t1 = float(grid[0]), float(grid[-1])
    found = [(float(t), None) for t in model.breakpoints(t0, t1)]
    found += [(float(t), (dx, dv)) for t, dx, dv in model.jumps if t0 < t <= t1]
    out = []
    for t, jump in found:
        k = min(int(np.searchsorted(grid, t)), len(grid) - 1)
        if k > 0 and abs(grid[k - 1] - t) <= 1e-9 * h:
            k -= 1
        if abs(grid[k] - t) <= 1e-9 * h:
            if k > 0:
                out.append((k, None, jump))
        else:
            out.append((k, t, jump))
    return out


def _dense_gauss(model: Model, result: Result, dense: Callable) -> tuple[np.ndarray, ...]:
    """Cumulative dissipated and input energy by Gauss-Legendre on the pieces of each output step between force
    discontinuities, the velocities from the method's dense output."""
    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    s, w = 0.5 * (nodes + 1), 0.5 * weights
    grid = result.time
    h = (grid[-1] - grid[0]) / (len(grid) - 1)
    events = _events(model, grid, h)
    inner = [t for k, t, _ in events if t is not None]
    edges = np.unique(np.concatenate([grid, inner]))
    a, b = edges[:-1], edges[1:]
    times = (a[:, None] + (b - a)[:, None] * s[None, :]).ravel()
    jumps = [(k, t, jump) for k, t, jump in events if t is not None and jump is not None]
    # the output at a jump's time is its right limit: the state just after it
    asked = np.concatenate([[grid[0]], times, [t for _, t, _ in jumps]])
    order = np.argsort(asked, kind="stable")  # the solver takes sorted times
    x_sorted, v_sorted = dense(asked[order])
    x_all, v_all = np.empty_like(x_sorted), np.empty_like(v_sorted)
    x_all[order], v_all[order] = x_sorted, v_sorted
    v = v_all[1:1 + len(times)].reshape(len(a), GAUSS_POINTS, model.n)
    pieces = np.stack([_dissipation(model, v) @ w, _input_power(model, v, times) @ w]) * (b - a)
    step = np.zeros((2, len(grid)))
    np.add.at(step, (slice(None), np.searchsorted(grid, b - 1e-9 * h)), pieces)
    for (k, _, jump), x_after, v_after in zip(jumps, x_all[1 + len(times):], v_all[1 + len(times):]):
        step[1, k] += _jump_work(model, np.concatenate([x_after - jump[0], v_after - jump[1]]), jump)
    step[1] += _jumps_on_grid(model, result, events)
    return np.cumsum(step[0]), np.cumsum(step[1])


def _jumps_on_grid(model: Model, result: Result, events) -> np.ndarray:
    """The work of the ground's jumps that fall on output points, booked there (the output is after the jump)."""
    work = np.zeros(len(result.time))
    for k, t, jump in events:
        if t is None and jump is not None:
            before = np.concatenate([result.displacement[k] - jump[0], result.velocity[k] - jump[1]])
            work[k] += _jump_work(model, before, jump)
    return work


def _hermite_gauss(model: Model, result: Result) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative dissipated and input energy on the quintic Hermite interpolant of each step: its quadratic
    powers (x'^T C x') exactly, as a Gram form of the step's ends, and the rest (the forces' power, quadratic
    dampers) by Gauss-Legendre."""
    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_POINTS)
    s, w = 0.5 * (nodes + 1), 0.5 * weights
    # h x'(s) = sum of these slopes times (x1 - x0, h v0, h^2 a0, h v1, h^2 a1): x0's slope is -x1's (the basis
    # sums to 1), so the ends enter as the step's difference and no digits cancel between x0 and x1
    slope = hermite_slopes(s)[:, [3, 1, 2, 4, 5]]
    gram = slope.T @ (w[:, None] * slope)  # int_0^1 of their products: exact, degree 8 under Gauss's 15
    t, x, v, a = result.time, result.displacement, result.velocity, result.acceleration
    moving = moving_columns(x, v, a)  # DOFs at rest throughout (a wave's far ones) add no power: left out
    forms = _damper_forms(model, moving)
    projected = [P for P in (model.B if model.signals else None,
                             model.quadratic.D.T if model.quadratic is not None else None) if P is not None]
    if moving is not None:
        (x, v, a), projected = (q[:, moving] for q in (x, v, a)), [P[moving] for P in projected]
    N, n = x.shape
    step = np.zeros((2, N))
    chunk = max(2, _CHUNK_VALUES // (4 * max(n, 1)))
    for lo in range(0, N - 1, chunk - 1):  # rows lo .. hi - 1: their steps lo + 1 .. hi - 1
        hi = min(N, lo + chunk)
        h = np.diff(t[lo:hi])
        step[0, lo + 1:hi] = sum((gram_power(gram, h, *(form(y[lo:hi]) for y in (x, v, a))) for form in forms),
                                 np.zeros(hi - lo - 1))
        if projected:
            rates = [node_rates(slope, h, *(y[lo:hi] @ P for y in (x, v, a))) for P in projected]
            if model.signals:  # the forces' power: each force's value times the rate it acts on (x' B)
                times = t[lo:hi - 1, None] + h[:, None] * s[None, :]
                step[1, lo + 1:hi] = (_forces_power(model, rates.pop(0), times.ravel()) @ w) * h
            if model.quadratic is not None:
                step[0, lo + 1:hi] += (_quadratic_dampers(model, rates.pop(0)) @ w) * h
    events = _events(model, t, (t[-1] - t[0]) / (N - 1))
    interrupted: dict[int, list] = {}  # no smooth interpolant spans these steps
    for k, time, jump in events:
        interrupted.setdefault(k, []).extend([(time, jump)] if time is not None else [])
    for k, inner in interrupted.items():
        inner.sort(key=lambda event: event[0])
        step[:, k] = _reintegrated_step(model, t[k - 1], t[k], result.displacement[k - 1], result.velocity[k - 1],
                                        inner)
    step[1] += _jumps_on_grid(model, result, events)
    return np.cumsum(step[0]), np.cumsum(step[1])


def _reintegrated_step(model: Model, ta: float, tb: float, x: np.ndarray, v: np.ndarray, inner) -> np.ndarray:
    """A step's dissipated energy and input work along the flow from the run's state at its start, across the
    force discontinuities and ground jumps inside it (DOP853, rtol 1e-12): what the Hermite interpolant of a
    smooth motion cannot give; the difference from the run is the step's own error, as for the closed form."""
    from scipy.integrate import solve_ivp

    from smdcli.solvers.base import force_function

    n = model.n
    z = np.concatenate([x, v, [0.0, 0.0]])
    scale = max(float(np.abs(z).max()), 1e-300)
    t = ta
    for t_event, jump in [*inner, (tb, None)]:
        if t_event > t:
            u = force_function(model, t, t_event) if model.signals else (lambda time: np.empty(0))

            def flow(time, y, u=u):
                values, velocity = u(time), y[n:2 * n]
                power = velocity @ (model.B @ values) if len(values) else 0.0
                return np.concatenate([model.rhs(time, y[:2 * n], values),
                                       [_dissipation(model, velocity), power]])

            z = solve_ivp(flow, (t, t_event), z, method="DOP853", rtol=1e-12, atol=1e-14 * scale).y[:, -1]
        if jump is not None:
            z[2 * n + 1] += _jump_work(model, z[:2 * n], jump)
            z[:n] += jump[0]
            z[n:2 * n] += jump[1]
        t = t_event
    return z[2 * n:]
