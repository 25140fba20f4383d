"""Lognormal fragility curves, P(collapse | IM = x) = Phi(ln(x / theta) / beta), fitted by maximum likelihood
(Baker 2015): to the collapse intensities of an incremental dynamic analysis (each record's, a lognormal sample:
theta the exponential of their log mean, beta their log standard deviation with the 1/n variance), or to
multiple-stripe counts (z_j collapses of n_j runs at intensity x_j: the binomial likelihood, maximized by Newton's
method on (ln theta, beta) with its exact gradient and Hessian). Each parameter's 95 % interval is its profile
likelihood's: where twice the log-likelihood, maximized over the other parameter, falls 3.84 (chi-square, one
degree of freedom) below its maximum.

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

CHI2_95 = 3.841458820694124  # the chi-square distribution's 95 % point, one degree of freedom
NEWTON_STEPS = 100


@dataclass(frozen=True)
class Fragility:
    """A fitted lognormal fragility: its median theta (the IM's units), dispersion beta, their 95 % profile-likelihood
    intervals, the log-likelihood at the optimum, and the data it was fitted to."""

    theta: float
    beta: float
    theta_95: tuple[float, float]
    beta_95: tuple[float, float]
    log_likelihood: float
    method: str  # "collapse intensities" or "multiple stripes"
    im: np.ndarray  # the collapse intensities, or the stripes' intensities
    runs: np.ndarray | None = None  # per stripe
    collapses: np.ndarray | None = None

    def probability(self, im) -> np.ndarray:
        """P(collapse) at intensities im."""
        from scipy.special import ndtr

        return ndtr(np.log(np.asarray(im, dtype=float) / self.theta) / self.beta)


def from_collapse_intensities(im) -> Fragility:
    """The lognormal fitted to each record's collapse intensity (all positive, at least two distinct)."""
    x = np.log(np.asarray(im, dtype=float))
    n = len(x)
    mu, beta = float(x.mean()), float(x.std())  # the 1/n variance: the maximum-likelihood estimate
    if not beta > 0:
        raise ValueError(f"expected collapse intensities that differ, found {n} equal to {math.exp(mu):g}")
    # theta's profile: beta^2(theta) = beta^2 + (ln theta - mu)^2, so n ln(1 + d^2 / beta^2) = chi2 at d = +-width
    width = beta * math.sqrt(math.expm1(CHI2_95 / n))
    low, high = (beta * r for r in _dispersion_interval(n))
    log_likelihood = float(-n * math.log(beta) - n / 2 - n * math.log(math.sqrt(2 * math.pi)) - x.sum())
    return Fragility(math.exp(mu), beta, (math.exp(mu - width), math.exp(mu + width)), (low, high), log_likelihood,
                     "collapse intensities", np.exp(x))


def _dispersion_interval(n: int) -> tuple[float, float]:
    """The roots r of n (ln r + (1 / r^2 - 1) / 2) = chi2 / 2: beta's profile-likelihood interval over its estimate
    (r = b / beta_hat), one each side of 1."""
    from scipy.optimize import brentq

    def drop(r):
        return n * (math.log(r) + (1 / (r * r) - 1) / 2) - CHI2_95 / 2
    lo = 1.0
    while drop(lo) < 0:
        lo /= 2
    hi = 1.0
    while drop(hi) < 0:
        hi *= 2
    return (brentq(drop, lo, 1.0, xtol=1e-15, rtol=1e-15), brentq(drop, 1.0, hi, xtol=1e-15, rtol=1e-15))


def _binomial(im, runs, collapses, mu: float, beta: float) -> tuple[float, np.ndarray, np.ndarray]:
    """The multiple-stripe log-likelihood at (mu = ln theta, beta), its gradient and Hessian in (mu, beta)."""
    from scipy.special import log_ndtr

    u = (np.log(im) - mu) / beta
    log_p, log_q = log_ndtr(u), log_ndtr(-u)
    value = float((collapses * log_p + (runs - collapses) * log_q).sum())
    phi = np.exp(-0.5 * u * u) / math.sqrt(2 * math.pi)
    a, b = phi / np.exp(log_p), phi / np.exp(log_q)  # the inverse Mills ratios of each side
    s = collapses * a - (runs - collapses) * b  # d value / d u per stripe (a' = -u a - a^2, b' = -u b + b^2)
    ds = collapses * (-u * a - a * a) + (runs - collapses) * (u * b - b * b)
    du_dmu, du_dbeta = -1.0 / beta, -u / beta
    gradient = np.array([(s * du_dmu).sum(), (s * du_dbeta).sum()])
    # d2u/dmu dbeta = 1 / beta^2, d2u/dbeta2 = 2 u / beta^2, d2u/dmu2 = 0
    hessian = np.array([[(ds * du_dmu * du_dmu).sum(), (ds * du_dmu * du_dbeta + s / beta ** 2).sum()],
                        [0.0, (ds * du_dbeta * du_dbeta + s * 2 * u / beta ** 2).sum()]])
    hessian[1, 0] = hessian[0, 1]
    return value, gradient, hessian


def from_stripes(im, runs, collapses) -> Fragility:
    """The lognormal fitted to multiple-stripe counts by the binomial likelihood (Baker 2015): Newton's method on
    (ln theta, beta) from the moments of the collapse fractions, each step halved until the likelihood grows."""
    im, runs, collapses = (np.asarray(q, dtype=float) for q in (im, runs, collapses))
    fraction = collapses / runs
    if not (fraction.max() > 0 and fraction.min() < 1 and len(np.unique(im)) >= 2):
        raise ValueError("expected stripes with some collapses and some survivals, at two intensities at least: the "
                         "lognormal is not identified otherwise")
    outcome = np.isin(fraction, (0.0, 1.0))
    if outcome.all() and im[fraction == 0].max() < im[fraction == 1].min():
        raise ValueError("the likelihood has no maximum at a finite dispersion (every stripe below "
                         f"{im[fraction == 1].min():g} survives, every one from there collapses: a step): add stripes "
                         "between them")
    mu, beta = _start(im, fraction)
    value, gradient, hessian = _binomial(im, runs, collapses, mu, beta)
    for _ in range(NEWTON_STEPS):
        try:
            step = -np.linalg.solve(hessian, gradient)
        except np.linalg.LinAlgError:
            step = gradient
        if gradient @ step <= 0:  # not an ascent direction: the gradient's
            step = gradient * (abs(beta) / max(np.abs(gradient).max(), 1e-300))
        size = 1.0
        while True:
            trial = (mu + size * step[0], beta + size * step[1])
            if trial[1] > 0:
                found = _binomial(im, runs, collapses, *trial)
                if found[0] >= value:
                    break
            size /= 2
            if size < 1e-12:
                break
        if size < 1e-12:
            break
        (mu, beta), (value, gradient, hessian) = trial, found
        if np.abs(size * step).max() <= 1e-15 * max(abs(mu), beta, 1.0):
            break
    if not (np.isfinite(beta) and beta > 0 and np.abs(gradient).max() <= 1e-8 * max(1.0, abs(value))):
        raise ValueError("the likelihood has no maximum at a finite dispersion (the collapses rise as a step "
                         "between two stripes): add stripes between them")
    theta_95 = tuple(math.exp(v) for v in _profile(im, runs, collapses, mu, beta, value, 0))
    beta_95 = _profile(im, runs, collapses, mu, beta, value, 1)
    return Fragility(math.exp(mu), beta, theta_95, beta_95, value, "multiple stripes", im, runs, collapses)


def _start(im: np.ndarray, fraction: np.ndarray) -> tuple[float, float]:
    """(ln theta, beta) from a least-squares line through the probits of the stripes' collapse fractions."""
    from scipy.special import ndtri

    inside = np.clip(fraction, 0.02, 0.98)
    slope, intercept = np.polyfit(np.log(im), ndtri(inside), 1)
    if not slope > 0:
        return float(np.log(im).mean()), 1.0
    return float(-intercept / slope), float(1 / slope)


def _profile(im, runs, collapses, mu: float, beta: float, best: float, which: int) -> tuple[float, float]:
    """Parameter `which`'s (0: ln theta, 1: beta) 95 % profile-likelihood interval: where twice the log-likelihood,
    maximized over the other parameter, falls CHI2_95 below its maximum."""
    from scipy.optimize import brentq, minimize_scalar

    estimate = (mu, beta)[which]

    def profiled(value: float) -> float:
        if which == 0:
            other = minimize_scalar(lambda b: -_binomial(im, runs, collapses, value, b)[0],
                                    bounds=(1e-6 * beta, 100 * beta), method="bounded",
                                    options={"xatol": 1e-12 * beta})
        else:
            other = minimize_scalar(lambda m: -_binomial(im, runs, collapses, m, value)[0],
                                    bounds=(mu - 50 * beta, mu + 50 * beta), method="bounded",
                                    options={"xatol": 1e-12 * max(abs(mu), 1.0)})
        return 2 * (best + other.fun) - CHI2_95
    ends = []
    for side in (-1, 1):
        step = 0.1 * beta
        far = estimate + side * step
        while profiled(far) < 0:
            step *= 2
            far = estimate + side * step
            if which == 1 and far <= 0:
                far = estimate * 1e-9
                break
        ends.append(brentq(profiled, min(estimate, far), max(estimate, far), xtol=1e-13 * max(abs(estimate), 1.0)))
    return ends[0], ends[1]
