"""Response-spectrum analysis of a linear multi-DOF scene under support acceleration: the modes, their participation
in the ground motion's direction, each mode's peak from a spectrum, and the peaks combined (SRSS, CQC, ABSSUM).

Every DOF moves with the ground (influence vector r of ones). Mode n, mass-normalised phi_n: participation
Gamma_n = phi_n^T M r, effective mass Gamma_n^2; its peak displacement Gamma_n phi_n Sa(T_n, zeta_n) / w_n^2. CQC
correlates modes i and j by Der Kiureghian's coefficient at their own damping ratios.

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

COMBINATIONS = ("cqc", "srss", "abssum")


@dataclass(frozen=True)
class ModalParticipation:
    """Per mode (in order of frequency): period, circular frequency, damping ratio, participation factor,
    effective modal mass and its cumulative ratio to the total mass; shapes mass-normalised, (n, modes)."""

    period: np.ndarray
    omega: np.ndarray
    damping: np.ndarray
    participation: np.ndarray
    effective_mass: np.ndarray
    cumulative_ratio: np.ndarray
    shapes: np.ndarray
    total_mass: float


def modal_participation(M: np.ndarray, K: np.ndarray, C: np.ndarray, influence: np.ndarray | None = None
                        ) -> ModalParticipation:
    """Undamped modes of (K, M), each with the damping ratio phi^T C phi / (2 w) (exact for classical damping, the
    usual approximation otherwise) and its participation in the ground motion along `influence` (default ones)."""
    from scipy.linalg import eigh

    n = len(M)
    r = np.ones(n) if influence is None else np.asarray(influence, dtype=float)
    squared, shapes = eigh(K, M)
    lead = np.argmax(np.abs(shapes) >= (1 - 1e-6) * np.abs(shapes).max(axis=0), axis=0)
    shapes = shapes * np.where(shapes[lead, np.arange(n)] < 0, -1.0, 1.0)  # a sign chosen, not left to LAPACK
    omega = np.sqrt(np.maximum(squared, 0.0))
    damping = (shapes * (C @ shapes)).sum(axis=0) / (2 * omega)
    gamma = shapes.T @ (M @ r)
    effective = gamma**2
    total = float(r @ M @ r)
    return ModalParticipation(2 * math.pi / omega, omega, damping, gamma, effective, np.cumsum(effective) / total,
                              shapes, total)


def cqc_correlation(omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Der Kiureghian's correlation coefficients rho_ij of modal peaks, (modes, modes), 1 on the diagonal."""
    wi, wj = omega[:, None], omega[None, :]
    zi, zj = zeta[:, None], zeta[None, :]
    r = wj / wi
    numerator = 8 * np.sqrt(zi * zj) * (zi + r * zj) * r**1.5
    denominator = (1 - r * r) ** 2 + 4 * zi * zj * r * (1 + r * r) + 4 * (zi * zi + zj * zj) * r * r
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = numerator / denominator
    rho[np.isnan(rho)] = 0.0  # undamped modes of different frequency do not correlate
    np.fill_diagonal(rho, 1.0)
    return rho


def combine(modal: np.ndarray, rule: str, rho: np.ndarray | None = None) -> np.ndarray:
    """Combined peaks of modal peak values (modes, quantities) by a rule: SRSS, CQC (with rho) or ABSSUM."""
    if rule == "srss":
        return np.sqrt((modal**2).sum(axis=0))
    if rule == "abssum":
        return np.abs(modal).sum(axis=0)
    if rule == "cqc":
        return np.sqrt(np.maximum(np.einsum("iq,ij,jq->q", modal, rho, modal), 0.0))
    raise ValueError(f"unknown combination {rule!r}: expected one of {', '.join(COMBINATIONS)}")


@dataclass(frozen=True)
class ResponseSpectrumAnalysis:
    """Modal peaks (modes, quantity) and their combinations by rule: displacement of each DOF, force and
    deformation of each element (springs), base shear."""

    modes: ModalParticipation
    used: int  # the modes combined (the lowest ones)
    Sa: np.ndarray  # spectral acceleration at each used mode's period and damping, m/s^2
    displacement: np.ndarray  # (used, n) modal peaks
    deformation: np.ndarray  # (used, elements)
    force: np.ndarray  # (used, elements)
    base_shear: np.ndarray  # (used,)
    rho: np.ndarray

    def combined(self, rule: str) -> dict[str, np.ndarray]:
        """Peak displacement, element deformation, element force and base shear by a combination rule."""
        rho = self.rho
        return {"displacement": combine(self.displacement, rule, rho),
                "deformation": combine(self.deformation, rule, rho),
                "force": combine(self.force, rule, rho),
                "base_shear": combine(self.base_shear[:, None], rule, rho)[0]}


def response_spectrum_analysis(M: np.ndarray, K: np.ndarray, C: np.ndarray, spectral_acceleration,
                               modes: int | None = None, elements: tuple = (), influence=None
                               ) -> ResponseSpectrumAnalysis:
    """The modal peaks of a scene under a spectrum: spectral_acceleration(period, damping) -> Sa in m/s^2 (arrays
    in, array out); `elements` are (a, b, k) with node indices (-1: ground) whose deformation x_b - x_a and force
    k (x_b - x_a) are reported; base shear is the effective mass times Sa of each mode."""
    found = modal_participation(M, K, C, influence)
    used = len(found.omega) if modes is None else min(modes, len(found.omega))
    w, zeta = found.omega[:used], found.damping[:used]
    Sa = np.asarray(spectral_acceleration(found.period[:used], zeta), dtype=float)
    displacement = (found.participation[:used] * Sa / w**2)[:, None] * found.shapes[:, :used].T
    padded = np.concatenate([displacement, np.zeros((used, 1))], axis=1)  # index -1: the ground, at rest
    a = np.array([e[0] for e in elements], dtype=int)
    b = np.array([e[1] for e in elements], dtype=int)
    k = np.array([e[2] for e in elements], dtype=float)
    deformation = padded[:, b] - padded[:, a] if len(elements) else np.zeros((used, 0))
    return ResponseSpectrumAnalysis(found, used, Sa, displacement, deformation, deformation * k,
                                    found.effective_mass[:used] * Sa, cqc_correlation(w, zeta))
