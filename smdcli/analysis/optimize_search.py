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
        if not limits or violation(problem, lower + theta * width) == 0 and all(
                problem.evaluate(lower + theta * width, m)[0] < limit * (1 - 1e-6) for m, limit in problem.constraints):
            theta = _polished(problem, theta, lower, width, history)  # no constraint binds: a smooth optimum
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
        if seen_value < value * (1 - 1e-12) and violation(problem, lower + seen * width) == 0:  # strictly met
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
    kept only where the gradient shrinks and the objective does not grow."""
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
        if not (np.abs(trial_g).max() < np.abs(g).max() and trial_value <= value * (1 + 1e-14)):
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
