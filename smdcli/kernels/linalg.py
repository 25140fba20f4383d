"""Dense LU with partial pivoting, in place and without allocation, for the implicit kernels' iteration
matrices (a LAPACK call through numpy allocates its result and costs more than the arithmetic for the
few DOFs most scenes have).

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from smdcli.kernels.compiler import no_alloc


@no_alloc
def lu_factor(A, piv):
    """Factor A = P L U in place (L below the diagonal, unit diagonal implied); False when A is singular."""
    n = A.shape[0]
    for k in range(n):
        p = k
        biggest = abs(A[k, k])
        for r in range(k + 1, n):
            if abs(A[r, k]) > biggest:
                biggest, p = abs(A[r, k]), r
        piv[k] = p
        if biggest == 0.0:
            return False
        if p != k:
            for q in range(n):
                A[k, q], A[p, q] = A[p, q], A[k, q]
        pivot = A[k, k]
        for r in range(k + 1, n):
            factor = A[r, k] / pivot
            A[r, k] = factor
            if factor != 0.0:
                for q in range(k + 1, n):
                    A[r, q] -= factor * A[k, q]
    return True


@no_alloc
def lu_solve(LU, piv, b):
    """Overwrite b with A^-1 b, from lu_factor's LU and pivots."""
    n = LU.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for r in range(1, n):
        s = b[r]
        for q in range(r):
            s -= LU[r, q] * b[q]
        b[r] = s
    for r in range(n - 1, -1, -1):
        s = b[r]
        for q in range(r + 1, n):
            s -= LU[r, q] * b[q]
        b[r] = s / LU[r, r]


@no_alloc
def factor_shifted(J, diagonal, scale, LU, piv):
    """LU = diagonal I - scale J, factored in place (real or complex diagonal): the implicit methods' iteration
    matrices. False when it is singular."""
    size = J.shape[0]
    for r in range(size):
        for q in range(size):
            LU[r, q] = -scale * J[r, q]
        LU[r, r] += diagonal
    return lu_factor(LU, piv)
