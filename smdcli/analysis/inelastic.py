"""Inelastic response spectra of a ground acceleration record: constant-ductility (the yield strength that gives a
target ductility demand) and constant-strength (the ductility demand of a given strength), for elastoplastic and
bilinear oscillators, each solved exactly event to event (smdcli.kernels.inelastic).

For a period T, damping zeta and normalised strength eta = fy / f0 (f0 = k u0, the elastic oscillator's peak
force, u0 its peak deformation), the ductility demand is mu(eta) = max |u| / u_y with u_y = eta u0. mu(1) = 1.
Several strengths can give one ductility (mu(eta) is not monotonic); the largest is reported, as is standard: eta
is scanned down from 1 on a log grid and the first bracket of the target refined by false position (Illinois,
bisection where it stalls) until mu is within TOLERANCE of the target. All oscillators of a scan or of a
refinement round run in one threaded kernel call.

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from smdcli.scenario.spec import STANDARD_GRAVITY

TOLERANCE = 1e-9  # relative, on the ductility demand
SCAN = np.geomspace(1.0, 1e-3, 61)  # eta: from elastic down to a strength reduction of 1000
SCAN_CHUNK = 8
MAX_ROUNDS = 100
LAWS = ("elastoplastic", "bilinear")


@dataclass(frozen=True)
class InelasticSpectrum:
    """Per target (ductility or strength), damping and period, (K, Z, P) each: the yield strength coefficient
    Cy = fy / (m g), the strength reduction factor Ry = f0 / fy, the ductility demand mu, the peak deformation
    (m) and the residual (final plastic) deformation (m); and the elastic peak deformation u0 (Z, P)."""

    kind: str  # "ductility" or "strength"
    targets: np.ndarray
    period: np.ndarray
    damping: np.ndarray
    hardening: float
    Cy: np.ndarray
    Ry: np.ndarray
    ductility: np.ndarray
    peak_deformation: np.ndarray
    residual_deformation: np.ndarray
    elastic_deformation: np.ndarray
    found: np.ndarray  # (K, Z, P) bool: a strength was found (constant ductility) or the run is defined

    @property
    def elastic_Sa(self) -> np.ndarray:
        """The elastic pseudo-acceleration (m/s^2), (Z, P)."""
        return (2 * math.pi / self.period) ** 2 * self.elastic_deformation


def _elastic(time, acceleration, omega, zeta):
    """The elastic peak |u| per oscillator, by the same kernel (never yielding)."""
    from smdcli.kernels.inelastic import peaks

    found = peaks(acceleration, float(time[1] - time[0]), omega, zeta, np.inf, 0.0)
    return np.maximum(found[:, 0], -found[:, 1])


def _run(time, acceleration, omega, zeta, uy, hardening):
    """(peak |u|, final plastic deformation) per oscillator."""
    from smdcli.kernels.inelastic import peaks

    found = peaks(acceleration, float(time[1] - time[0]), omega, zeta, uy, hardening)
    return np.maximum(found[:, 0], -found[:, 1]), found[:, 2]


def constant_strength(time, acceleration, periods, dampings, strengths, hardening: float = 0.0
                      ) -> InelasticSpectrum:
    """The ductility demand of oscillators of yield strength coefficient Cy = fy / (m g), per Cy, damping, period."""
    periods, dampings, strengths = (np.asarray(x, dtype=float) for x in (periods, dampings, strengths))
    K, Z, P = len(strengths), len(dampings), len(periods)
    w = np.broadcast_to(2 * math.pi / periods, (K, Z, P))
    zeta = np.broadcast_to(dampings[None, :, None], (K, Z, P))
    cy = np.broadcast_to(strengths[:, None, None], (K, Z, P))
    u0 = _elastic(time, acceleration, w[0].ravel(), zeta[0].ravel()).reshape(Z, P)
    uy = cy * STANDARD_GRAVITY / w**2
    peak, residual = (x.reshape(K, Z, P) for x in _run(time, acceleration, w.ravel(), zeta.ravel(), uy.ravel(),
                                                        hardening))
    with np.errstate(divide="ignore", invalid="ignore"):
        Ry = w**2 * u0[None] / (cy * STANDARD_GRAVITY)
    return InelasticSpectrum("strength", strengths, periods, dampings, hardening, np.array(cy), Ry, peak / uy, peak,
                             residual, u0, np.isfinite(peak))


def constant_ductility(time, acceleration, periods, dampings, ductilities, hardening: float = 0.0,
                       advance=None) -> InelasticSpectrum:
    """The largest yield strength giving each target ductility demand, per target, damping and period."""
    periods, dampings, targets = (np.asarray(x, dtype=float) for x in (periods, dampings, ductilities))
    K, Z, P = len(targets), len(dampings), len(periods)
    w_zp = np.broadcast_to(2 * math.pi / periods, (Z, P)).ravel()
    zeta_zp = np.broadcast_to(dampings[:, None], (Z, P)).ravel()
    u0 = _elastic(time, acceleration, w_zp, zeta_zp)  # (Z*P,)
    O, S = Z * P, len(SCAN)
    # mu over the scan of eta, down from 1 in chunks: an oscillator leaves the scan once it reaches every target
    mu_scan = np.full((O, S), np.nan)
    mu_scan[:, 0] = 1.0  # eta = 1: elastic, the peak exactly at the surface
    scanning = np.flatnonzero(u0 > 0)
    for lo in range(1, S, SCAN_CHUNK):
        if not len(scanning):
            break
        cols = np.arange(lo, min(S, lo + SCAN_CHUNK))
        eta = np.tile(SCAN[cols], len(scanning))
        rows = np.repeat(scanning, len(cols))
        peak, _ = _run(time, acceleration, w_zp[rows], zeta_zp[rows], eta * u0[rows], hardening)
        mu_scan[scanning[:, None], cols[None, :]] = (peak / (eta * u0[rows])).reshape(len(scanning), len(cols))
        scanning = scanning[~(np.nanmax(mu_scan[scanning], axis=1) >= targets.max())]
    if advance is not None:
        advance(O)
    # the first bracket from the top for each (oscillator, target): mu(lo) >= target > mu(hi), eta lo < hi
    lo = np.full((O, K), np.nan)
    hi = np.full((O, K), np.nan)
    mu_lo = np.full((O, K), np.nan)
    mu_hi = np.full((O, K), np.nan)
    exact = np.zeros((O, K), dtype=bool)
    for k, target in enumerate(targets):
        if target == 1.0:
            lo[:, k] = hi[:, k] = 1.0
            mu_lo[:, k] = mu_hi[:, k] = 1.0
            exact[:, k] = True
            continue
        reached = np.nan_to_num(mu_scan) >= target
        first = np.argmax(reached, axis=1)
        ok = reached.any(axis=1) & (u0 > 0)
        rows = np.flatnonzero(ok)
        lo[rows, k] = SCAN[first[rows]]
        hi[rows, k] = SCAN[first[rows] - 1]
        mu_lo[rows, k] = mu_scan[rows, first[rows]]
        mu_hi[rows, k] = mu_scan[rows, first[rows] - 1]
        exact[rows, k] = np.abs(mu_lo[rows, k] - target) <= TOLERANCE * target
    best_eta = np.where(exact, lo, np.nan)
    best_mu = np.where(exact, mu_lo, np.nan)
    side = np.zeros((O, K))  # Illinois: which end was kept last time
    active = np.isfinite(lo) & ~exact
    for _ in range(MAX_ROUNDS):
        rows, cols = np.nonzero(active)
        if not len(rows):
            break
        t = targets[cols]
        a, b = np.log(lo[rows, cols]), np.log(hi[rows, cols])
        fa, fb = mu_lo[rows, cols] - t, mu_hi[rows, cols] - t
        x = (a * fb - b * fa) / (fb - fa)
        stalled = ~((x > a) & (x < b)) | (np.abs(side[rows, cols]) > 2)
        x = np.where(stalled, 0.5 * (a + b), x)
        trial = np.exp(x)
        peak, _ = _run(time, acceleration, w_zp[rows], zeta_zp[rows], trial * u0[rows], hardening)
        mu = peak / (trial * u0[rows])
        f = mu - t
        done = np.abs(f) <= TOLERANCE * t
        upper = f < 0  # mu below the target: the strength is too high, the bracket's upper end moves down
        hi[rows[upper], cols[upper]] = trial[upper]
        mu_hi[rows[upper], cols[upper]] = mu[upper]
        lo[rows[~upper], cols[~upper]] = trial[~upper]
        mu_lo[rows[~upper], cols[~upper]] = mu[~upper]
        # Illinois: halve the kept end's residual when the same end is kept twice in a row
        kept = np.where(upper, 1.0, -1.0)
        repeat = np.sign(side[rows, cols]) == kept
        side[rows, cols] = np.where(repeat, side[rows, cols] + kept, kept)
        narrow = np.log(hi[rows, cols] / lo[rows, cols]) <= 1e-15
        finished = done | narrow
        best_eta[rows[finished], cols[finished]] = trial[finished]
        best_mu[rows[finished], cols[finished]] = mu[finished]
        active[rows[finished], cols[finished]] = False
    shape = (Z, P, K)
    eta_zpk = best_eta.reshape(shape)
    mu_zpk = best_mu.reshape(shape)
    u0_zp = u0.reshape(Z, P)
    w_p = 2 * math.pi / periods
    uy = eta_zpk * u0_zp[..., None]
    final = np.isfinite(eta_zpk)
    residual = np.full(shape, np.nan)
    if final.any():
        idx = np.nonzero(final)
        zeta_f = dampings[idx[0]]
        w_f = w_p[idx[1]]
        _, res = _run(time, acceleration, w_f, zeta_f, uy[idx], hardening)
        residual[idx] = res
    move = (2, 0, 1)  # (Z, P, K) -> (K, Z, P)
    Cy = (w_p[None, :, None] ** 2 * uy / STANDARD_GRAVITY).transpose(move)
    with np.errstate(divide="ignore", invalid="ignore"):
        Ry = (1.0 / eta_zpk).transpose(move)
    return InelasticSpectrum("ductility", targets, periods, dampings, hardening, Cy, Ry, mu_zpk.transpose(move),
                             (mu_zpk * uy).transpose(move), residual.transpose(move), u0_zp, final.transpose(move))
