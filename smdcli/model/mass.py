"""M^-1 A without forming M^-1.

Must not import: anything of smd (the bottom of the model layer).
"""

from __future__ import annotations

import numpy as np


def is_diagonal(M) -> bool:
    """Whether a mass matrix (or a stack of them) is diagonal: every element-form scene's, a sparse scene's always."""
    if not isinstance(M, np.ndarray):
        return True
    return np.count_nonzero(M) == np.count_nonzero(np.diagonal(M, axis1=-2, axis2=-1))


def mass_solve(M: np.ndarray, A: np.ndarray) -> np.ndarray:
    """M^-1 A for mass matrices (n, n) or stacks of them: a division where M is diagonal (an O(n^3) solve of a
    3,000-DOF diagonal M took 1.6 s), else a solve."""
    if is_diagonal(M):
        diagonal = M.diagonal() if not isinstance(M, np.ndarray) else np.diagonal(M, axis1=-2, axis2=-1)
        return A / diagonal[..., :, None]
    return np.linalg.solve(M, A)


def reciprocal_masses(M) -> np.ndarray | None:
    """Each DOF's 1 / m where M is diagonal, else None."""
    return 1.0 / M.diagonal() if is_diagonal(M) else None
