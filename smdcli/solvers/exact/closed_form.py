"""Closed-form free response of a linear 1-DOF oscillator, all four regimes.

m x'' + c x' + k x = 0 has roots -s +- mu with s = c/(2m), mu^2 = s^2 - k/m.
Writing x = e^{-st} (x0 Ch(t) + (v0 + s x0) Sh(t)) with Ch = cosh(mu t) and
Sh = sinh(mu t)/mu (cos and sin/|mu| when mu^2 < 0) covers every regime with
one formula. Sh and Ch are entire functions of z = mu^2 t^2, evaluated by
Taylor series near z = 0, so the response is smooth across zeta = 1 instead
of switching formulas on float equality as the book's SMDsysSim does.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math
import time

import numpy as np

from smdcli.model import Model
from smdcli.result import Result, SolverStats
from smdcli.solvers.base import Solver, Tolerances, make_result, stated_rounding

_SERIES_BELOW = 1e-3  # |z| under which the Taylor series is used (error < 1e-20)


def _even_odd(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ch = cosh(sqrt z) and Sh/t = sinh(sqrt z)/sqrt z for real z of either sign (cos, sin for z < 0)."""
    ch = np.empty_like(z)
    sh = np.empty_like(z)
    small = np.abs(z) < _SERIES_BELOW
    zs = z[small]
    ch[small] = 1 + zs / 2 * (1 + zs / 12 * (1 + zs / 30 * (1 + zs / 56)))
    sh[small] = 1 + zs / 6 * (1 + zs / 20 * (1 + zs / 42 * (1 + zs / 72)))
    neg = (~small) & (z < 0)
    r = np.sqrt(-z[neg])
    ch[neg], sh[neg] = np.cos(r), np.sin(r) / r
    pos = (~small) & (z > 0)
    r = np.sqrt(z[pos])
    ch[pos], sh[pos] = np.cosh(r), np.sinh(r) / r
    return ch, sh


def free_response(m: float, c: float, k: float, x0: float, v0: float, t: np.ndarray):
    """Displacement and velocity of the free oscillator at times t (measured from the start)."""
    s = c / (2 * m)
    mu2 = s * s - k / m
    t = np.asarray(t, dtype=float)
    if mu2 > 0 and math.sqrt(mu2) * t.max(initial=0.0) > 20:
        # Overdamped and long: use the two exponentials, which never overflow.
        mu = math.sqrt(mu2)
        r_fast = -s - mu
        r_slow = -(k / m) / (s + mu)  # = -s + mu without cancellation
        a = (v0 - r_fast * x0) / (r_slow - r_fast)
        b = x0 - a
        e_slow, e_fast = np.exp(r_slow * t), np.exp(r_fast * t)
        return a * e_slow + b * e_fast, a * r_slow * e_slow + b * r_fast * e_fast
    ch, sh = _even_odd(mu2 * t * t)
    sh = sh * t
    decay = np.exp(-s * t)
    x = decay * (x0 * ch + (v0 + s * x0) * sh)
    v = decay * (v0 * ch - (s * v0 + (k / m) * x0) * sh)
    return x, v


class ClosedForm(Solver):
    """Analytic free response of a 1-DOF linear oscillator."""

    linear_only = True
    adaptive = False

    def refuse(self, model: Model) -> str | None:
        problem = super().refuse(model)
        if problem:
            return problem
        if model.n != 1:
            return f"'closed_form' needs one DOF; this model has {model.n}; try 'exact'"
        if model.is_forced:
            return f"'closed_form' is the free response; {model.force_paths[0]} applies a force; try 'exact'"
        return None

    def solve(self, model: Model, grid: np.ndarray, tol: Tolerances) -> Result:
        start = time.perf_counter()
        m, c, k = model.M[0, 0], model.C[0, 0], model.K[0, 0]
        x, v = free_response(m, c, k, model.x0[0], model.v0[0], grid - grid[0])
        # exp(lambda t) of a large argument carries the argument's rounding: u |lambda| t relative.
        rate = abs(c / (2 * m)) + math.sqrt(abs(k / m) + (c / (2 * m)) ** 2)
        arguments = 1 + rate * float(grid[-1] - grid[0])
        stated = stated_rounding(int(min(arguments, 1e15))) if math.isfinite(arguments) else 1.0
        stats = SolverStats(method=self.name, requested_method=self.name, reason="",
                            wall_time_s=time.perf_counter() - start, stated_accuracy=stated)
        return make_result(model, grid, x[:, None], v[:, None], stats)
