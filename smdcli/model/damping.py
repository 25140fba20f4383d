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
        masses = np.diag(M)
        if np.count_nonzero(M) == np.count_nonzero(masses) and np.all(masses > 0):
            # a diagonal M: the standard problem of M^-1/2 K M^-1/2 (numpy's; scipy's generalized one costs 4x
            # on a small scene, where a sensitivity's stencil builds this 18 times)
            root = 1.0 / np.sqrt(masses)
            squared, shapes = np.linalg.eigh(K * root[:, None] * root[None, :])
            shapes = shapes * root[:, None]
        else:
            from scipy.linalg import eigh

            squared, shapes = eigh(K, M)
        ratios = np.broadcast_to(np.asarray(spec.modal, dtype=float), squared.shape)
        left = M @ shapes
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
