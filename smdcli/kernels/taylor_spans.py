"""Where a Taylor step's terms can be other than zero (smdcli.kernels.taylor): a wave that has not reached a DOF
leaves its x and v zero, and the series spreads a DOF's terms to its neighbours an order or two at a time, so a step
works out only the DOFs the motion has reached and those its terms reach from them.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

from smdcli.kernels.compiler import inlined, no_alloc


@inlined
def terms_span(first, last, k, width, orders, n):
    """The DOFs where order k of the series can be other than zero, (lowest, highest + 1), when order 0 and the loads
    are zero outside DOFs first..last-1 and the rows couple DOFs within width of each other, a coupling each `orders`
    orders (coupling_orders)."""
    if first >= last:
        return 0, 0
    distance = (k + orders - 1) // orders * width
    return max(first - distance, 0), min(last + distance, n)


@no_alloc
def coupling_orders(band, spans):
    """The orders of the series it takes its terms to spread from a DOF to the next within the band (diagonals): 2
    where the damping couples no two DOFs (x's order k + 1 is v's order k at the same DOF; v's takes the neighbours' x
    of order k), else 1 (v's takes the neighbours' v too; and where the rows are not held as diagonals)."""
    w = band.shape[1] // 2
    if band.shape[1] == 0:
        return 1
    for j in range(band.shape[1]):
        if j != w and spans[1, j, 0] < spans[1, j, 1]:
            return 1
    return 2


@no_alloc
def active_dofs(y, first, last, lowest, highest, floor_x, floor_v):
    """The DOFs first..last-1 widened to every DOF within lowest..highest-1 where y's |x| or |v| passes its floor; y
    zeroed in lowest..highest-1 outside them. A wave that has not reached a mass leaves its terms far under the step's
    tolerance (the series spreads p DOFs a step ahead of the wave, at sizes that fall by orders of magnitude a DOF),
    and the series skips them: a 1,000-mass chain driven at one end for 10 s works out 138 of them at most."""
    n = len(y) // 2
    if first >= last:
        first, last = highest, lowest
    for i in range(lowest, min(first, highest)):
        if abs(y[i]) > floor_x or abs(y[n + i]) > floor_v:
            first = i
            break
    for i in range(highest - 1, max(last, lowest) - 1, -1):
        if abs(y[i]) > floor_x or abs(y[n + i]) > floor_v:
            last = i + 1
            break
    if first >= last:
        first, last = lowest, lowest
    for i in range(lowest, first):
        y[i], y[n + i] = 0.0, 0.0
    for i in range(max(last, lowest), highest):
        y[i], y[n + i] = 0.0, 0.0
    return (first, last) if first < last else (0, 0)


@no_alloc
def loaded_dofs(m, y):
    """The span of DOFs that move or are loaded at the start, (first, last + 1): y's x or v not zero, a force or an
    element acting; (0, n) where the ground is forced (the load is on every DOF), (0, 0) for none."""
    n = m.n
    first, last = n, np.int64(0)  # int64s, not literals (one compile of active_dofs)
    for j in range(len(m.f_dof)):
        if m.f_dof[j] < 0:
            return 0, n
        first, last = min(first, m.f_dof[j]), max(last, m.f_dof[j] + 1)
    for e in range(len(m.el_a)):
        for dof in (m.el_a[e], m.el_b[e]):
            if dof >= 0:
                first, last = min(first, dof), max(last, dof + 1)
    return active_dofs(y, first, last, np.int64(0), n, 0.0, 0.0)
