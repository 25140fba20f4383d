"""Sparse scenes: more than SPARSE_DOFS masses, assembled as CSR matrices, with the products, modes and bounds
that keep them O(n) in memory (a 10,000-mass chain's dense M, C and K would hold 2.4 GB).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.model.modes import RIGID_BODY, Modes, modal_eigenvalues, regime, signed
from smdcli.errors import ScenarioError
from smdcli.scenario import Scenario

# Above this many masses an element-form scene is assembled sparse (is_sparse_scene) and auto solves it by
# extrapolated sparse Newmark: from 1,000 masses on that met rtol 1e-6 in less time than the exact modal solution
# (measured on chains: 0.39 s against 1.15 s at 2,000, 0.62 s against 2.35 s at 3,000), whose n x n modes also grow
# as n^2 in memory and n^3 in time where M^-1/2 K M^-1/2 is not tridiagonal.
SPARSE_DOFS = 2000
# The most cubic springs and quadratic dampers a sparse scene holds: each is a dense row of the model's incidence
# tables (n numbers), and the compiled march visits every one at every Newton iteration.
SPARSE_NONLINEAR = 64


def cheapest(A: np.ndarray):
    """A as it multiplies cheapest: CSR where at most a tenth of its entries are nonzero (a chain's banded matrices,
    O(n) a vector instead of O(n^2)), else itself."""
    if not isinstance(A, np.ndarray) or A.shape[0] < 64 or np.count_nonzero(A) > A.size // 10:
        return A
    from scipy.sparse import csr_matrix

    return csr_matrix(A)


# values of q a sparse product takes together (8 rows of 10,000 DOFs: as fast as all 1,001 rows at once, its
# transposes in cache; a sweep's million rows of 100 DOFs in 1,500 products, not 125,000)
VALUES_AT_ONCE = 2 ** 16


def rows_times(q: np.ndarray, A) -> np.ndarray:
    """q @ A over q's last axis, A dense or CSR (from cheapest), in q's row-major layout: a sparse product takes
    VALUES_AT_ONCE of q's values at a time, transposed in cache, where one product of all rows (A^T q^T)^T left its
    result column-major, and the copy every later reader made of it (HDF5 writes rows) cost 8 times the product."""
    if isinstance(A, np.ndarray):
        return q @ A
    flat = np.reshape(q, (-1, q.shape[-1]))
    transposed = A.T
    out = np.empty((len(flat), A.shape[1]), dtype=np.result_type(flat.dtype, A.dtype))
    block = max(1, VALUES_AT_ONCE // max(flat.shape[1], 1))
    for start in range(0, len(flat), block):
        rows = slice(start, start + block)
        out[rows] = (transposed @ np.ascontiguousarray(flat[rows].T)).T
    return out.reshape(q.shape[:-1] + (A.shape[1],))


def symmetric(A) -> bool:
    """A equals its transpose to rounding (dense or CSR)."""
    return bool(abs(A - A.T).max() <= 1e-13 * abs(A).max())


SPARSE_MODES = 20  # a sparse scene's modes: the lowest this many


def lowest_modes(model) -> Modes:
    """A sparse scene's lowest SPARSE_MODES undamped modes (shift-invert Lanczos about zero), each with the damping
    ratio of its diagonal of Phi^T C Phi: exact where the damping is classical, the undamped modes' projection of it
    elsewhere."""
    from scipy.sparse.linalg import eigsh

    k = min(SPARSE_MODES, model.n - 2)
    squared, shapes = eigsh(model.K.tocsc(), k=k, M=model.M.tocsc(), sigma=-1e-6 * abs(model.K).max(), which="LM")
    order = np.argsort(squared)
    squared, shapes = np.maximum(squared[order], 0.0), shapes[:, order]
    shapes = shapes / np.sqrt((shapes * (model.M @ shapes)).sum(axis=0))  # mass-normalized
    wn = np.sqrt(squared)
    c = (shapes * (model.C @ shapes)).sum(axis=0)
    zeta = np.where(wn > 0, c / (2 * np.where(wn > 0, wn, 1.0)), np.inf)
    rigid = wn <= RIGID_BODY * model.omega_max
    return Modes(modal_eigenvalues(c, squared), wn, zeta,
                 tuple(regime(z, 0.0 if r else w) for z, w, r in zip(zeta, wn, rigid)), signed(shapes))


def is_sparse_scene(scenario: Scenario) -> bool:
    """Assembled sparse: a scene of more than SPARSE_DOFS DOFs, in element form or with [system]'s matrices read
    from files (M diagonal: the sparse methods invert it row by row), whose every part the sparse path takes
    (linear springs and dampers, up to SPARSE_NONLINEAR cubic springs and quadratic dampers, Rayleigh [damping]; no
    hysteretic spring, contact, stop, modal [damping] or ground motion, which need the modes or the dense
    matrices)."""
    system = scenario.system
    if system is not None and not (system.from_files and is_diagonal(system.M)):
        return False
    nonlinear = sum(e.law in ("cubic", "quadratic") for e in scenario.springs + scenario.dampers)
    return (len(scenario.dof_names) > SPARSE_DOFS and not scenario.frictions
            and not scenario.stops and all(s.nonsmooth is None for s in scenario.springs)
            and nonlinear <= SPARSE_NONLINEAR and scenario.ground_motion is None
            and (scenario.damping is None or not scenario.damping.modal))


def is_diagonal(matrix) -> bool:
    """A sparse matrix (zeros not stored) with no entry off its diagonal."""
    return matrix.nnz == np.count_nonzero(matrix.diagonal())


def assembled(stamp, n: int, sparse: bool):
    """An n x n matrix of (rows, columns, values), duplicates summed: CSR for a sparse scene, else dense."""
    rows, columns, values = (np.asarray(list(part)) for part in stamp)
    if sparse:
        from scipy.sparse import coo_matrix

        return coo_matrix((values.astype(float), (rows.astype(int), columns.astype(int))), shape=(n, n)).tocsr()
    A = np.zeros((n, n))
    if len(values):
        with np.errstate(over="ignore", invalid="ignore"):
            np.add.at(A, (rows.astype(int), columns.astype(int)), values)
    return A


def gershgorin_omega(model) -> float:
    """Gershgorin's bound on a sparse scene's highest natural frequency, sqrt(max_i sum_j |K_ij| / m_i): Lanczos
    converges slowly where a chain's top modes crowd (7.6 s at 10,000 masses); the bound is tight on a uniform
    chain."""
    return math.sqrt(float((abs(model.K) @ np.ones(model.n) / model.M.diagonal()).max()))


def gershgorin_rate(model) -> float:
    """A bound on the largest |eigenvalue| of a sparse scene's state matrix [[0, I], [-M^-1 K, -M^-1 C]]: a mode's
    |lambda| is at most its c_j + omega_j (c_j / 2 m_j + its root), so at most Gershgorin's bound on M^-1 C's plus
    gershgorin_omega."""
    return float((abs(model.C) @ np.ones(model.n) / model.M.diagonal()).max()) + gershgorin_omega(model)


DENSE_FILE_BYTES = 1_600_000_000  # the most M, C and K read from files may take when made dense (10,000 DOFs: 2.4 GB)


DENSE_MATRICES = 12  # n x n doubles a linear solve holds at its peak (9.8 GB measured for 10,000 masses)


def check_dense_size(scenario: Scenario) -> None:
    """Refuse, before anything is assembled, a scene kept dense (not is_sparse_scene) whose dense matrices could not
    fit in memory, saying why it is not kept sparse where it is large enough to be. A sparse scene's memory grows
    with its elements and its output (which MAX_SAMPLES bounds): it passes."""
    from smdcli.resources import fits, physical_memory

    n = len(scenario.dof_names)
    needed = DENSE_MATRICES * 8.0 * n * n
    if not fits(needed) and not is_sparse_scene(scenario):
        why = f" (kept dense because {_why_dense(scenario)})" if n > SPARSE_DOFS else ""
        raise ScenarioError(scenario.path, "system.dofs" if scenario.system is not None else "mass",
                            f"{n} DOFs need about {needed / 2**30:.3g} GB for their dense matrices{why}, more than "
                            f"half of this machine's {physical_memory() / 2**30:.3g} GB; model fewer masses")


def _why_dense(scenario: Scenario) -> str:
    """Why a scene of more than SPARSE_DOFS DOFs is not kept sparse."""
    if scenario.system is not None and not scenario.system.from_files:
        return "its [system] matrices are written inline (read from files, a lumped M is kept sparse)"
    if scenario.system is not None and not is_diagonal(scenario.system.M):
        return "M is not diagonal (the sparse methods need a lumped mass matrix)"
    nonlinear = sum(e.law in ("cubic", "quadratic") for e in scenario.springs + scenario.dampers)
    if nonlinear > SPARSE_NONLINEAR:
        return f"it has {nonlinear} cubic springs and quadratic dampers (a sparse scene holds {SPARSE_NONLINEAR})"
    return ("the scene has parts the sparse methods do not take (stops, friction, hysteretic springs, modal "
            "[damping] or ground motion)")


def dense_file_matrices(scenario: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[system]'s file matrices made dense, for a scene the sparse path does not take; refused, naming why, where
    they would not fit in memory."""
    system = scenario.system
    n = len(system.dofs)
    if 3 * 8 * n * n > DENSE_FILE_BYTES:
        why = _why_dense(scenario)
        raise ScenarioError(scenario.path, "system.M", f"{n} DOFs would be solved with dense matrices "
                            f"({3 * 8 * n * n / 1e9:.1f} GB) because {why}; the limit is "
                            f"{DENSE_FILE_BYTES / 1e9:.1f} GB")
    return system.dense()
