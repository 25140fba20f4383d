"""The linear rows of a scene, [-M^-1 K, -M^-1 C], held as diagonals where M is diagonal and the DOFs are numbered
along a narrow band (a chain's half-width is 1): one product of the rows with a state is then a pass over contiguous
rows per diagonal, which vectorizes, instead of a sparse row's gather. The Taylor series' recurrence
(smdcli.kernels.taylor) takes one such product an order.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.kernels.compiler import inlined, kernel

MAX_BAND = 8  # widest half-band held as diagonals; wider rows stay sparse (CSR)


@kernel
def diagonals(m):
    """The rows [-M^-1 K, -M^-1 C] as diagonals, band[part, w + d, i] = A[i, part n + i + d] for a half-width w, each
    diagonal's span [first, last) of rows that are not zero (spans[part, w + d]; first == last where it is all zero:
    a chain's damping is often one damper), and M^-1's diagonal, where M^-1 is diagonal and w is at most MAX_BAND: one
    order's product is then a pass over contiguous rows per diagonal, which vectorizes, instead of a sparse row's
    gather. An empty band where not."""
    n = m.n
    w = 0
    for i in range(n):
        if m.mi_ptr[i + 1] - m.mi_ptr[i] != 1 or m.mi_idx[m.mi_ptr[i]] != i:
            return np.zeros((2, 0, n)), np.zeros((2, 0, 2), dtype=np.int64), np.zeros(n)
        for q in range(m.a_ptr[i], m.a_ptr[i + 1]):
            w = max(w, abs(m.a_idx[q] % n - i))
    if w > MAX_BAND or 2 * w + 1 > n:
        return np.zeros((2, 0, n)), np.zeros((2, 0, 2), dtype=np.int64), np.zeros(n)
    band = np.zeros((2, 2 * w + 1, n))
    minv_diagonal = np.zeros(n)
    for i in range(n):
        minv_diagonal[i] = m.mi_val[m.mi_ptr[i]]
        for q in range(m.a_ptr[i], m.a_ptr[i + 1]):
            column = m.a_idx[q]
            band[column // n, w + column % n - i, i] += m.a_val[q]
    spans = np.zeros((2, 2 * w + 1, 2), dtype=np.int64)
    for part in range(2):
        for j in range(2 * w + 1):
            first, last = n, 0
            for i in range(n):
                if band[part, j, i] != 0.0:
                    first, last = min(first, i), i + 1
            if first < last:
                spans[part, j, 0], spans[part, j, 1] = first, last
    return band, spans, minv_diagonal


@inlined
def banded_rows(m, band, spans, minv_diagonal, below, work, ground, inverse, row, first, last):
    """row[n + first:n + last] = (A below - ground + M^-1 work) inverse, A held as diagonals with their spans
    (diagonals) and work not zero only at forces' and elements' DOFs, where it is read and zeroed (not a pass over
    every DOF); the rows outside [first, last) are the caller's (zero where below's terms reach no further)."""
    n = len(minv_diagonal)
    target = row[n:]
    for i in range(first, last):
        target[i] = -ground
    for part in range(2):
        add_diagonals(band, spans, part, below, 1.0, target, first, last)
    moved_loads(m, minv_diagonal, work, 1.0, target)
    for i in range(first, last):
        target[i] *= inverse


@inlined
def tridiagonal_rows(m, band, spans, minv_diagonal, below, work, ground, inverse, row, first, last):
    """banded_rows for a half-width of one (a chain numbered along it): the three diagonals of M^-1 K, the load on
    the ground and the order's scaling in one pass over the DOFs, where a pass each cost a loop's overhead each, then
    M^-1 C's diagonals over their spans (a chain damped at one mass: one entry)."""
    n = len(minv_diagonal)
    target = row[n:]
    for i in (0, n - 1):  # the ends, where a neighbour is missing
        if first <= i < last:
            s = -ground
            for j in range(3):
                column = i + j - 1
                if 0 <= column < n:
                    s += band[0, j, i] * below[column]
            target[i] = s * inverse
    # slices, so that the loop's index starts at 0 (see add_diagonals)
    a, b = max(first, 1), min(last, n - 1)
    if a < b:
        lower, diagonal, upper = band[0, 0, a:b], band[0, 1, a:b], band[0, 2, a:b]
        x_lower, x_at, x_upper = below[a - 1:b - 1], below[a:b], below[a + 1:b + 1]
        inner = target[a:b]
        for i in range(b - a):
            inner[i] = (lower[i] * x_lower[i] + diagonal[i] * x_at[i] + upper[i] * x_upper[i] - ground) * inverse
    add_diagonals(band, spans, 1, below, inverse, target, first, last)
    moved_loads(m, minv_diagonal, work, inverse, target)


@inlined
def add_diagonals(band, spans, part, below, scale, target, lowest, highest):
    """target[lowest:highest] += (the part's diagonals times below) scale (part 0: M^-1 K on x, 1: M^-1 C on v),
    each diagonal over its span only."""
    n = len(target)
    w = band.shape[1] // 2
    for j in range(2 * w + 1):
        d = j - w
        first = max(spans[part, j, 0], -d, lowest)
        last = min(spans[part, j, 1], n - d, highest)
        if first >= last:
            continue
        # slices, so that the loop's index starts at 0: numba checks a possibly negative index, which would keep the
        # loop from vectorizing
        entries, part_target = band[part, j, first:last], target[first:last]
        source = below[part * n + d + first:part * n + d + last]
        for i in range(last - first):
            part_target[i] += entries[i] * source[i] * scale


@inlined
def moved_loads(m, minv_diagonal, work, scale, target):
    """target += M^-1 work scale at the DOFs of the forces and the elements (moved_into)."""
    for j in range(len(m.f_dof)):
        moved_into(m.f_dof[j], minv_diagonal, work, scale, target)
    for e in range(len(m.el_a)):
        moved_into(m.el_a[e], minv_diagonal, work, scale, target)
        moved_into(m.el_b[e], minv_diagonal, work, scale, target)


@inlined
def moved_into(dof, minv_diagonal, work, scale, target):
    """target[dof] += M^-1 work scale at a DOF (none where dof < 0, the ground), work[dof] zeroed: a DOF that several
    forces share is added once."""
    if dof >= 0:
        target[dof] += minv_diagonal[dof] * work[dof] * scale
        work[dof] = 0.0
