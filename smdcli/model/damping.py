"""[damping]: the C that Rayleigh or modal damping adds, and the check that no mode gains energy.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.errors import ScenarioError
from smdcli.scenario import Scenario


def added_damping(scenario: Scenario, M: np.ndarray, K: np.ndarray) -> np.ndarray:
    """[damping]'s C: alpha M + beta K (K the linear stiffness), or M Phi diag(2 zeta_i w_i) Phi^T M from the
    undamped modes (Phi mass-normalized); refused where the total C would let a mode gain energy."""
    spec = scenario.damping
    if spec.modal:
        standard = _standard_modes(M, K)
        if standard is not None:  # M Phi = L V: M's root times the standard problem's eigenvectors
            root, _, squared, V = standard
            left = root[:, None] * V
        else:
            from scipy.linalg import eigh

            squared, shapes = eigh(K, M)
            left = M @ shapes
        ratios = np.broadcast_to(np.asarray(spec.modal, dtype=float), squared.shape)
        return (left * (2 * ratios * np.sqrt(np.maximum(squared, 0.0)))) @ left.T
    return spec.alpha * M + spec.beta * K


def check_damping(C: np.ndarray, scenario: Scenario) -> None:
    """With [damping], the total C must be positive semidefinite: otherwise some motion gains energy."""
    if scenario.damping is None:
        return
    if isinstance(C, np.ndarray):
        lowest, largest = float(np.linalg.eigvalsh(C).min(initial=0.0)), float(np.abs(C).max(initial=0.0))
    else:  # a sparse scene's: Lanczos for the lowest eigenvalue alone
        from scipy.sparse.linalg import eigsh

        lowest, largest = float(eigsh(C, k=1, which="SA", tol=1e-10)[0][0]), float(abs(C).max())
    if lowest < -1e-12 * max(largest, 1e-300):
        key = "damping.modal" if scenario.damping.modal else "damping"
        raise ScenarioError(scenario.path, key, f"makes the damping matrix indefinite (eigenvalue {lowest:.4g} N s/m): "
                                                "some mode would be negatively damped; expected damping >= 0")


def modal_damping_derivative(scenario: Scenario, M: np.ndarray, K: np.ndarray, dM: np.ndarray, dK: np.ndarray
                             ) -> tuple[np.ndarray, float] | None:
    """d/dp of modal damping's C (added_damping's) where M and K move by dM and dK per unit of p, exactly, and the
    rounding that reaches it relative to its largest entry: C = L f(A) L with M = L L (diagonal), A = L^-1 K L^-1 = V
    diag(lambda) V^T and f(lambda_i) = 2 zeta_i sqrt(lambda_i); d f(A) = V ((V^T dA V) o G) V^T (Daleckii and Krein),
    G_ij the divided difference of f (f' on the diagonal; 2 zeta / (sqrt(lambda_i) + sqrt(lambda_j)) where the ratios
    are equal, with no cancellation). None where it is not this form or has no such derivative: M not diagonal,
    a mode at zero frequency (sqrt has no slope there), two modes of different ratios at one frequency."""
    standard = _standard_modes(M, K)
    if standard is None or np.count_nonzero(dM) != np.count_nonzero(np.diag(dM)):
        return None
    root, A, squared, V = standard
    if squared[0] <= 1e-12 * abs(squared[-1]):
        return None
    ratios = np.broadcast_to(np.asarray(scenario.damping.modal, dtype=float), squared.shape)
    w = np.sqrt(squared)
    f = 2 * ratios * w
    same = ratios[:, None] == ratios[None, :]
    gap = squared[:, None] - squared[None, :]
    apart = np.abs(gap) > 1e-8 * squared[-1]
    if np.any(~same & ~apart & ~np.eye(len(w), dtype=bool)):
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        G = np.where(same, 2 * ratios[:, None] / (w[:, None] + w[None, :]),
                     (f[:, None] - f[None, :]) / np.where(apart, gap, 1.0))
    half = np.diag(dM) / (2 * np.diag(M))  # L^-1 dL
    dA = dK / root[:, None] / root[None, :] - half[:, None] * A - A * half[None, :]
    F = (V * f) @ V.T
    dF = V @ ((V.T @ dA @ V) * G) @ V.T
    dL = half * root
    dC = dL[:, None] * F * root[None, :] + root[:, None] * dF * root[None, :] + root[:, None] * F * dL[None, :]
    # eigenvectors good to eps over the gaps they are divided by: the spread of the G's over their diagonal's
    conditioning = float(np.abs(G).max() / np.abs(np.diag(G)).min()) * np.sqrt(squared[-1] / squared[0])
    return dC, float(np.finfo(float).eps) * len(w) * conditioning


def _standard_modes(M: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """For a diagonal M = L L: (L's diagonal, A = L^-1 K L^-1, A's eigenvalues (the modes' squared frequencies,
    ascending) and eigenvectors V), by numpy's standard eigenproblem (scipy's generalized one costs 4x on a small
    scene, where a sensitivity's stencil makes this 18 times); None for any other M."""
    masses = np.diag(M)
    if np.count_nonzero(M) != np.count_nonzero(masses) or not np.all(masses > 0):
        return None
    root = np.sqrt(masses)
    A = K / root[:, None] / root[None, :]
    squared, V = np.linalg.eigh(A)
    return root, A, squared, V
