"""[system]'s M, C and K read from files a finite-element program writes: Matrix Market (.mtx), scipy sparse
(.npz, from scipy.sparse.save_npz, or numpy.savez of dense arrays) and MATLAB (.mat, v5 to v7.2 as scipy reads
them). Kept sparse: a 10,000-DOF chain's three matrices are 0.7 MB as CSR, 2.4 GB dense.

Must not import: model, solvers, or any layer above."""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np

from smdcli.scenario.reader import _Table

SUFFIXES = (".mtx", ".npz", ".mat")


def matrix_file_path(t: _Table, key: str) -> Path:
    """The file a [system] field names, relative to the scenario's folder."""
    path = Path(t.string(key))
    return path if path.is_absolute() else Path(t.file).parent / path


def read_matrix_file(t: _Table, key: str):
    """(the square matrix the file [system].KEY names, as CSR; the file's sha256): the file read once, for both;
    one clear line where it cannot be read or is not a real square matrix."""
    path = matrix_file_path(t, key)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise t.fail(key, f"expected a Matrix Market (.mtx), scipy (.npz) or MATLAB (.mat) file, found {path.name!r}")
    if not path.is_file():
        raise t.fail(key, f"{path}: no such file")
    try:
        data = path.read_bytes()
        matrix = {".mtx": _read_mtx, ".npz": _read_npz, ".mat": _read_mat}[suffix](io.BytesIO(data), key)
    except _Unreadable as exc:
        raise t.fail(key, f"{path}: {exc}") from None
    except (OSError, ValueError, TypeError, KeyError, IndexError, NotImplementedError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise t.fail(key, f"{path}: cannot be read as a {suffix} matrix ({reason})") from None
    from scipy.sparse import csr_matrix, issparse

    if not issparse(matrix):
        matrix = np.asarray(matrix)
        if matrix.ndim != 2:
            raise t.fail(key, f"{path}: expected a matrix, found an array of shape {matrix.shape}")
    if np.iscomplexobj(matrix.data if issparse(matrix) else matrix):
        raise t.fail(key, f"{path}: expected a real matrix, found complex entries")
    matrix = csr_matrix(matrix, dtype=float)
    if matrix.shape[0] != matrix.shape[1] or matrix.shape[0] == 0:
        raise t.fail(key, f"{path}: expected a square matrix, found {matrix.shape[0]} x {matrix.shape[1]}")
    matrix.sum_duplicates()
    matrix.eliminate_zeros()
    return matrix, hashlib.sha256(data).hexdigest()


class _Unreadable(Exception):
    """A file that is a matrix file but not one matrix of the kind asked for."""


def _read_mtx(source: io.BytesIO, key: str):
    from scipy.io import mmread

    return mmread(source)


def _read_npz(source: io.BytesIO, key: str):
    with np.load(source, allow_pickle=False) as data:
        names = list(data.files)
        if {"format", "shape", "data"} <= set(names):  # scipy.sparse.save_npz
            from scipy.sparse import load_npz

            source.seek(0)
            return load_npz(source)
        return _one_of(names, key, lambda name: data[name])


def _read_mat(source: io.BytesIO, key: str):
    from scipy.io import loadmat

    try:
        data = loadmat(source)
    except NotImplementedError:  # v7.3 files are HDF5
        raise _Unreadable("a MATLAB v7.3 file; save it with save(..., '-v7') for scipy to read") from None
    names = [name for name in data if not name.startswith("__")]
    return _one_of(names, key, lambda name: data[name])


def _one_of(names: list[str], key: str, get):
    """The array named as the field (M, C or K) where the file holds several, else its only one."""
    if key in names:
        return get(key)
    if len(names) == 1:
        return get(names[0])
    raise _Unreadable(f"holds {', '.join(names) or 'no arrays'}; expected one matrix or one named {key}")


def check_file_matrix(t: _Table, key: str, matrix, n: int | None, strict: bool, sized_by: str = "") -> None:
    """A file's matrix fit to be M (strict: definite) or C, K: of the scene's size, finite, symmetric, and definite
    (semi-definite for C and K) where it is narrow or small enough to factor (_factors); a large wide one's diagonal
    must be positive (non-negative), as a definite matrix's is."""
    path = matrix_file_path(t, key).name
    if n is not None and matrix.shape[0] != n:
        raise t.fail(key, f"{path}: expected a {n} x {n} matrix ({sized_by}), found {matrix.shape[0]} x "
                          f"{matrix.shape[1]}")
    if not np.isfinite(matrix.data).all():
        row = int(np.repeat(np.arange(matrix.shape[0]), np.diff(matrix.indptr))[~np.isfinite(matrix.data)][0])
        raise t.fail(key, f"{path}: expected finite numbers, found {matrix.data[~np.isfinite(matrix.data)][0]} in row {row}")
    scale = float(np.abs(matrix.data).max(initial=0.0)) or 1.0
    asymmetry = abs(matrix - matrix.T)
    if asymmetry.nnz and asymmetry.max() > 1e-12 * scale:
        i, j = (int(a[0]) for a in np.nonzero(asymmetry == asymmetry.max()))
        raise t.fail(key, f"{path}: expected a symmetric matrix, found {key}[{i}][{j}] = {matrix[i, j]:g} but "
                          f"{key}[{j}][{i}] = {matrix[j, i]:g}")
    need = "positive definite" if strict else "positive semi-definite"
    diagonal = matrix.diagonal()
    bad = np.flatnonzero(diagonal <= 0 if strict else diagonal < 0)
    if len(bad):
        raise t.fail(key, f"expected a symmetric {need} matrix; {path} has {key}[{bad[0]}][{bad[0]}] = "
                          f"{diagonal[bad[0]]:g}")
    if not _factors(matrix, 0.0 if strict else 1e-12 * scale * matrix.shape[0]):
        raise t.fail(key, f"expected a symmetric {need} matrix; {path} is not (its Cholesky factorization fails)")


def _factors(matrix, shift: float) -> bool:
    """Whether matrix + shift I has a Cholesky factor (the shift: the rounding a semi-definite matrix's zero may
    carry): dense for a small matrix; banded (LAPACK pbtrf, n b^2 for half-bandwidth b) where it is narrow, as a
    finite-element program's matrices in a good numbering are; dense up to DENSE_CHECK DOFs; True, unproven, for a
    wide matrix beyond that."""
    n = matrix.shape[0]
    coo = matrix.tocoo()
    width = int(np.abs(coo.row - coo.col).max(initial=0))
    if n <= DENSE_FIRST or n * (width + 1) ** 2 > BANDED_WORK:
        if n > DENSE_CHECK:
            return True
        try:
            np.linalg.cholesky(matrix.toarray() + shift * np.eye(n))
        except np.linalg.LinAlgError:
            return False
        return True
    from scipy.linalg import LinAlgError, cholesky_banded

    below = coo.row >= coo.col
    bands = np.zeros((width + 1, n))  # LAPACK's lower band storage: bands[i - j, j] = A[i, j]
    np.add.at(bands, (coo.row[below] - coo.col[below], coo.col[below]), coo.data[below])
    bands[0] += shift
    try:
        cholesky_banded(bands, lower=True, check_finite=False)
    except LinAlgError:
        return False
    return True


DENSE_CHECK = 2000  # up to this many DOFs a wide file's matrix is proven definite by factoring it (0.1 s at 2,000)
DENSE_FIRST = 300  # up to this many DOFs the dense factorization is the cheapest (no scipy.linalg to import)
BANDED_WORK = 10 ** 9  # n (b + 1)^2 up to which a narrow matrix is factored banded, whatever its size (about 0.3 s)
