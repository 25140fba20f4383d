"""The local searches of `smd optimize` (analysis/optimize.py): SLSQP in the bounds scaled to [0, 1], a largest of
several smooth pieces (a frequency response's peaks, the worst of several records) minimized as the epigraph it is,
constraints as inequalities with their exact gradients, a smooth optimum refined by Newton's method.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

FEASIBLE = 1e-8  # a constraint's relative excess that still meets it
TOLERANCE = 1e-15  # SLSQP's on the objective scaled to its start
STATIONARY = 1e-6  # the first-order conditions' residual (per bound width), relative to the objective, at convergence
ACTIVE = 1e-9  # pieces of a largest within this (relative) of it are active
ROUNDING = 1e-12  # an objective's relative change below this is its rounding: neither better nor worse


def violation(problem, values: np.ndarray) -> float:
    """The largest relative excess of a constraint's measure over its limit at values (0 where all are met)."""
    return max([0.0] + [problem.evaluate(values, m)[0] / limit - 1 for m, limit in problem.constraints])


def local_search(problem, start: np.ndarray, lower: np.ndarray, width: np.ndarray, scale: float):
    """One SLSQP run from start (in [0, 1]^P): ((theta, value), scipy's result, history of (theta, value)). A largest
    of several pieces is minimized as the epigraph min t, t >= each piece; the others directly."""
    from scipy.optimize import minimize

    history = []
    minimax = problem.minimax
    slots = problem.slots(problem.objective)

    def at(theta):
        value, gradient, detail = problem.evaluate(lower + np.clip(theta, 0.0, 1.0) * width)
        history.append((np.clip(theta, 0.0, 1.0).copy(), value))
        return value, gradient, detail

    box = [(0.0, 1.0)] * len(start)
    options = {"ftol": TOLERANCE, "maxiter": 200}
    P = len(start)
    limits = [_limit(problem, m, limit, lower, width, problem.slots(m), P + minimax)
              for m, limit in problem.constraints]
    if not minimax:
        def fun(theta):
            value, gradient, _ = at(theta)
            return value / scale, gradient * width / scale
        result = minimize(fun, start, jac=True, method="SLSQP", bounds=box, constraints=limits, options=options)
        theta = np.clip(result.x, 0.0, 1.0)
        binding = [(m, limit) for m, limit in problem.constraints
                   if problem.evaluate(lower + theta * width, m)[0] >= limit * (1 - 1e-6)]
        if not binding:
            theta = _polished(problem, theta, lower, width, history)  # no constraint binds: a smooth optimum
        elif violation(problem, lower + theta * width) <= FEASIBLE:
            theta = _polished_on(problem, theta, lower, width, history, binding)
        return _best_seen(problem, theta, lower, width, history), result, history

    def constraints(y):
        _, _, detail = at(y[:-1])
        values = y[-1] - detail[:, 1] / scale  # the pieces in their producer's order (largest first in time)
        return np.resize(values, slots) if len(values) < slots else values[:slots]

    def jacobian(y):
        _, _, detail = at(y[:-1])
        rows = np.hstack([-detail[:, 2:] * width / scale, np.ones((len(detail), 1))])
        return np.resize(rows, (slots, rows.shape[1])) if len(rows) < slots else rows[:slots]

    value0 = at(start)[0]
    result = minimize(lambda y: y[-1], np.append(start, value0 / scale), jac=lambda y: np.eye(len(y))[-1],
                      method="SLSQP", bounds=box + [(None, None)],
                      constraints=[{"type": "ineq", "fun": constraints, "jac": jacobian}] + limits, options=options)
    theta = np.clip(result.x[:-1], 0.0, 1.0)
    return _best_seen(problem, theta, lower, width, history), result, history


def _best_seen(problem, theta: np.ndarray, lower: np.ndarray, width: np.ndarray,
               history: list) -> tuple[np.ndarray, float]:
    """(theta, value) where a search ended, or the best point it evaluated that meets the constraints where that is
    better (SLSQP may stop on a failed line search past a better point: a nonsmooth time-domain peak)."""
    value = problem.evaluate(lower + theta * width)[0]
    for seen, seen_value in history:
        if seen_value < value * (1 - ROUNDING) and violation(problem, lower + seen * width) == 0:  # strictly met
            theta, value = seen, seen_value
    return theta, value


def _limit(problem, measure, limit: float, lower, width, slots: int, size: int) -> dict:
    """SLSQP's inequality for measure <= limit (every located peak of a receptance), scaled by the limit, over the
    first P of its size variables (the minimax's t after them)."""
    P = len(lower)

    def values(y):
        value, _, detail = problem.evaluate(lower + np.clip(y[:P], 0.0, 1.0) * width, measure)
        tops = detail[:, 1] if detail is not None else np.array([value])
        out = 1.0 - tops / limit
        return np.resize(out, slots) if detail is not None else out

    def jacobian(y):
        value, gradient, detail = problem.evaluate(lower + np.clip(y[:P], 0.0, 1.0) * width, measure)
        rows = -(detail[:, 2:] if detail is not None else gradient[None]) * width / limit
        rows = np.hstack([rows, np.zeros((len(rows), size - P))])
        return np.resize(rows, (slots, size)) if detail is not None else rows
    return {"type": "ineq", "fun": values, "jac": jacobian}


def _polished(problem, theta: np.ndarray, lower: np.ndarray, width: np.ndarray, history: list,
              steps: int = 4, h: float = 1e-5) -> np.ndarray:
    """A smooth objective's optimum refined by Newton's method on its exact gradient in the parameters off their
    bounds (the Hessian from central differences of the gradient): SLSQP stops where the objective stops changing,
    a flat optimum's parameters then known only to the square root of rounding (rms's damping to 4e-8). A step is
    kept only where the gradient shrinks and the objective does not grow beyond its rounding."""
    free = (theta > 1e-9) & (theta < 1 - 1e-9)
    if not free.any():
        return theta
    value, gradient, _ = problem.evaluate(lower + theta * width)
    g = (gradient * width)[free]
    for _ in range(steps):
        if not np.all(np.isfinite(g)) or np.abs(g).max() == 0:
            break
        columns = []
        for j in np.flatnonzero(free):
            shifted = [theta.copy(), theta.copy()]
            shifted[0][j] += h
            shifted[1][j] -= h
            up, down = ((problem.evaluate(lower + t * width)[1] * width)[free] for t in shifted)
            columns.append((up - down) / (2 * h))
        hessian = np.array(columns).T
        try:
            step = np.linalg.solve(0.5 * (hessian + hessian.T), -g)
        except np.linalg.LinAlgError:
            break
        trial = theta.copy()
        trial[free] = np.clip(theta[free] + step, 0.0, 1.0)
        trial_value, trial_gradient, _ = problem.evaluate(lower + trial * width)
        trial_g = (trial_gradient * width)[free]
        # the objective's own rounding (a Lyapunov solution's, 1e-14 of it on another CPU's BLAS) is no growth
        if not (np.abs(trial_g).max() < np.abs(g).max() and trial_value <= value * (1 + ROUNDING)):
            break
        theta, value, g = trial, trial_value, trial_g
        history.append((theta.copy(), value))
    return theta


def stationary(problem, theta: np.ndarray, lower: np.ndarray, width: np.ndarray) -> bool:
    """Whether the first-order conditions hold at theta (in [0, 1]^P) to STATIONARY: some convex combination of the
    active pieces' gradients (the objective's own where it is smooth), plus non-negative multiples of the binding
    constraints' and of the bounds' normals, vanishes. What SLSQP's "positive directional derivative in the line
    search" means at an optimum it can no longer improve on at rounding, told from a stall elsewhere."""
    from scipy.optimize import nnls

    values = lower + theta * width
    value, gradient, detail = problem.evaluate(values)
    if problem.minimax and detail is not None:
        pieces = detail[detail[:, 1] >= detail[:, 1].max() * (1 - ACTIVE), 2:] * width
    else:
        pieces = (gradient * width)[None]
    binding = [problem.evaluate(values, m)[1] * width for m, limit in problem.constraints
               if problem.evaluate(values, m)[0] >= limit * (1 - 1e-6)]
    P = len(theta)
    eye = np.eye(P)
    normals = [-eye[j] for j in range(P) if theta[j] <= 1e-9] + [eye[j] for j in range(P) if theta[j] >= 1 - 1e-9]
    # relative to the objective itself, or to the pieces' gradients where they are larger (per unit of each
    # parameter's bound width)
    scale = max(float(np.abs(pieces).max(initial=0.0)), abs(float(value)), 1e-300)
    weight = 1e3 * scale  # the row holding the pieces' weights to a sum of one
    A = np.zeros((P + 1, len(pieces) + len(binding) + len(normals)))
    A[:P, :len(pieces)] = pieces.T
    A[P, :len(pieces)] = weight
    for i, column in enumerate([*binding, *normals]):
        A[:P, len(pieces) + i] = column
    b = np.zeros(P + 1)
    b[P] = weight
    multipliers, _ = nnls(A, b)
    residual = A[:P] @ multipliers
    return bool(np.abs(residual).max() <= STATIONARY * scale and abs(multipliers[:len(pieces)].sum() - 1) < 1e-6)


def _polished_on(problem, theta: np.ndarray, lower: np.ndarray, width: np.ndarray, history: list, binding: list,
                 steps: int = 4, h: float = 1e-5) -> np.ndarray:
    """A smooth optimum on binding constraints (measure = limit) refined by Newton's method on its first-order
    conditions, grad f + sum lambda_i grad c_i = 0 and c_i = limit_i, in the parameters off their bounds (the
    Lagrangian's Hessian from central differences of its gradient, the multipliers by least squares to start):
    SLSQP leaves such an optimum known to the square root of rounding, as it leaves an unconstrained one. A step is
    kept only where the conditions' residual shrinks."""
    free = (theta > 1e-9) & (theta < 1 - 1e-9)
    if not free.any() or len(binding) >= free.sum():
        return theta

    def conditions(t, multipliers=None):  # (gradient of f, the constraints' gradient rows, their residuals), free
        values = lower + t * width
        g = (problem.evaluate(values)[1] * width)[free]
        rows = np.array([(problem.evaluate(values, m)[1] * width)[free] / limit for m, limit in binding])
        residual = np.array([problem.evaluate(values, m)[0] / limit - 1 for m, limit in binding])
        return g, rows, residual

    g, rows, residual = conditions(theta)
    multipliers = np.linalg.lstsq(rows.T, -g, rcond=None)[0]
    scale = max(float(np.abs(g).max()), 1e-300)

    def size(g, rows, residual, multipliers):
        return max(float(np.abs(g + rows.T @ multipliers).max()) / scale, float(np.abs(residual).max(initial=0.0)))
    current = size(g, rows, residual, multipliers)
    for _ in range(steps):
        columns = []
        for j in np.flatnonzero(free):
            shifted = [theta.copy(), theta.copy()]
            shifted[0][j] += h
            shifted[1][j] -= h
            up, down = (conditions(t) for t in shifted)
            columns.append(((up[0] + up[1].T @ multipliers) - (down[0] + down[1].T @ multipliers)) / (2 * h))
        hessian = np.array(columns).T
        hessian = 0.5 * (hessian + hessian.T)
        m = len(binding)
        system = np.block([[hessian, rows.T], [rows, np.zeros((m, m))]])
        try:
            step = np.linalg.solve(system, -np.concatenate([g + rows.T @ multipliers, residual]))
        except np.linalg.LinAlgError:
            break
        trial = theta.copy()
        trial[free] = np.clip(theta[free] + step[:free.sum()], 0.0, 1.0)
        trial_multipliers = multipliers + step[free.sum():]
        trial_conditions = conditions(trial)
        trial_size = size(*trial_conditions, trial_multipliers)
        if not trial_size < current:
            break
        theta, multipliers, current = trial, trial_multipliers, trial_size
        g, rows, residual = trial_conditions
        history.append((theta.copy(), problem.evaluate(lower + theta * width)[0]))
    return theta
