"""M^-1 A without forming M^-1.

Must not import: anything of smd (the bottom of the model layer).
"""

from __future__ import annotations

import numpy as np


def mass_solve(M: np.ndarray, A: np.ndarray) -> np.ndarray:
    """M^-1 A for mass matrices (n, n) or stacks of them: a division where M is diagonal (every element-form
    scene; an O(n^3) solve of a 3,000-DOF diagonal M took 1.6 s), else a solve."""
    if not isinstance(M, np.ndarray):  # a sparse scene's M, diagonal
        return A / M.diagonal()[:, None]
    diagonal = np.diagonal(M, axis1=-2, axis2=-1)
    if np.count_nonzero(M) == np.count_nonzero(diagonal):
        return A / diagonal[..., :, None]
    return np.linalg.solve(M, A)


def reciprocal_masses(M) -> np.ndarray | None:
    """Each DOF's 1 / m where M is diagonal (every element-form scene; a sparse scene's M always), else None."""
    masses = M.diagonal()
    if isinstance(M, np.ndarray) and np.count_nonzero(M) != np.count_nonzero(masses):
        return None
    return 1.0 / masses
