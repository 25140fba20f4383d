"""A yielding frame's run, compiled: the exact event-to-event solution (smdcli.kernels.yielding) of a scene whose only
nonlinear elements are elastoplastic cores (elastoplastic and bilinear springs) under forces linear between their
breakpoints (recorded ground accelerations, tables), with linear springs, dampers and [damping]. What `smd ida`
runs a record at a scale with: its demand (drifts, displacements) from the states on the grid and at the events,
as the general exact solver (piecewise.py) gives them, without the energy balance that solver also integrates.

Where the scene is another (friction, stops, a cubic spring, a smooth force, a ground displacement's jumps) or the
kernel cannot vouch for its mode (nearly defective eigenvectors), `solve_yielding` returns None: the general
solver runs.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import time

import numpy as np

from smdcli.model import Model
from smdcli.result import NonsmoothHistory, Result, SolverStats
from smdcli.solvers.base import make_result, stated_rounding

MAX_EVENTS = 200_000
_KINDS = ("yield", "unload")


def applies(model: Model) -> bool:
    """Whether the compiled kernel solves this scene: elastoplastic cores, linear elsewhere, piecewise-linear forces."""
    from smdcli.elements.elastoplastic import Elastoplastic

    if not model.is_piecewise_linear or model.is_sparse or model.jumps:
        return False
    if not all(isinstance(e.law, Elastoplastic) and e.belt == 0.0 for e in model.nonsmooth):
        return False
    for signal in model.signals:  # linear between breakpoints: a generator whose S^2 is 0 (tables, steps, constants)
        exo = signal.exo()
        if exo is None or np.any(exo.S @ exo.S):
            return False
    return True


def _forcing(model: Model, t0: float, t1: float) -> tuple[np.ndarray, ...]:
    """(breakpoints from t0 ending with inf, the force at each (right limit) and its slope after it, the ground's
    acceleration on every DOF there and its slope)."""
    from smdcli.model.system import GROUND_DOF

    inner = np.asarray(model.breakpoints(t0, t1), dtype=float)
    bt = np.unique(np.concatenate([[t0], inner[(inner > t0) & (inner < t1)]]))
    F0, F1, G0, G1 = (np.zeros((len(bt), model.n)) for _ in range(4))
    for column, signal, dof in zip(model.B.T, model.signals, model.force_dofs):
        exo = signal.exo()
        states = signal.exo_states(bt)  # right limits: u = g w, u' = g S w
        value, slope = states @ exo.g, states @ (exo.S.T @ exo.g)
        F0 += np.outer(value, column)
        F1 += np.outer(slope, column)
        if dof == GROUND_DOF:  # the ground's acceleration, under every DOF: the absolute one adds it
            G0 += value[:, None]
            G1 += slope[:, None]
    return np.append(bt, np.inf), F0, F1, G0, G1


def solve_yielding(model: Model, grid: np.ndarray, locate_acceleration: bool = False) -> Result | None:
    """The exact run on the compiled kernel, or None where it does not apply (the general solver's then); with
    locate_acceleration, each DOF's peak |absolute acceleration| located on the solution (Result.located_acceleration)."""
    from smdcli.elements.elastoplastic import MINUS, PLUS
    from smdcli.kernels.yielding import NOT_FINITE, OK, run

    if not applies(model) or len(grid) < 2:
        return None
    begin = time.perf_counter()
    elements = model.nonsmooth
    R = np.array([e.row for e in elements], dtype=float).reshape(len(elements), model.n)
    kc = np.array([e.law.core.k for e in elements], dtype=float)
    fyc = np.array([e.law.core.fy for e in elements], dtype=float)
    klin = np.array([e.law.linear_stiffness for e in elements], dtype=float)
    x0, v0 = np.asarray(model.x0, dtype=float), np.asarray(model.v0, dtype=float)
    states = [e.law.start(float(e.row @ x0), float(e.row @ v0)) for e in elements]
    mode0 = np.array([1 if s.mode == PLUS else -1 if s.mode == MINUS else 0 for s in states], dtype=np.int64)
    dp0 = np.array([s.internal["dp"] for s in states], dtype=float)
    bt, F0, F1, G0, G1 = _forcing(model, float(grid[0]), float(grid[-1]))
    N, n, E = len(grid), model.n, len(elements)
    X, V, A = np.empty((N, n)), np.empty((N, n)), np.empty((N, n))
    T, DP = np.empty((N, E)), np.empty((N, E))
    ev_t = np.empty(MAX_EVENTS)
    ev_e, ev_kind = np.empty(MAX_EVENTS, dtype=np.int64), np.empty(MAX_EVENTS, dtype=np.int64)
    ev_x, ev_v, ev_T = np.empty((MAX_EVENTS, n)), np.empty((MAX_EVENTS, n)), np.empty((MAX_EVENTS, E))
    Minv, K, C = (np.ascontiguousarray(q, dtype=float) for q in (model.Minv, model.K, model.C))
    peak, peak_t = np.zeros(n if locate_acceleration else 0), np.zeros(n if locate_acceleration else 0)
    status, count, reached = run(Minv, K, C, R, kc, fyc, klin, bt, F0, F1, x0, v0,
                                 mode0, dp0, np.asarray(grid, dtype=float), MAX_EVENTS, X, V, A, T, DP, ev_t, ev_e,
                                 ev_kind, ev_x, ev_v, ev_T, G0, G1, peak, peak_t)
    if status == NOT_FINITE:
        stats = SolverStats(method="exact", requested_method="exact", reason="", success=False,
                            message=f"failed: the motion is not finite at t = {reached:.6g} s: it diverged",
                            wall_time_s=time.perf_counter() - begin)
        nan = np.full((N, n), np.nan)
        return make_result(model, grid, nan, nan, stats, t_failed=float(reached))
    if status != OK:
        return None
    paths = tuple(e.path for e in elements)
    events = tuple((float(ev_t[i]), paths[ev_e[i]], _KINDS[ev_kind[i]]) for i in range(count))
    history = NonsmoothHistory(paths, tuple(e.kind for e in elements), T,
                               {f"{p}.plastic_deformation": DP[:, j] for j, p in enumerate(paths)}, events, {},
                               event_x=ev_x[:count].copy(), event_v=ev_v[:count].copy(),
                               event_tension=ev_T[:count].copy())
    h = float(grid[-1] - grid[0]) / (N - 1)
    stated = stated_rounding(N + 8 * count, max(1.0, float(model.omega_max) * h))
    kinds = {kind: sum(1 for *_, k in events if k == kind) for kind in _KINDS}
    told = ", ".join(f"{c} {kind}" for kind, c in kinds.items() if c) or "no events"
    stats = SolverStats(method="exact", requested_method="exact", reason="a yielding frame, event to event (compiled)",
                        steps_accepted=N - 1, wall_time_s=time.perf_counter() - begin, stated_accuracy=stated,
                        message=f"ok: event to event, {count} events ({told}), compiled")
    result = make_result(model, grid, X, V, stats, acceleration=A, nonsmooth=history)
    return result.changed(located_acceleration=peak) if locate_acceleration else result
