"""Compiled explicit Runge-Kutta pairs with error control, dense output and a stiffness watch.

Bogacki-Shampine 3(2) (ode23), Dormand-Prince 5(4) (ode45) and Dormand-Prince 8(5,3) with its
seventh-order interpolant, stepped exactly as scipy.integrate's RK23, RK45 and DOP853 step (same
tableaus, initial step, error norms and step factors), so each is checked against scipy's in tests.
The integration restarts at every cut (force discontinuity) as a new scipy solver would.

The stiffness watch costs O(elements) per step, not an eigenvalue problem: |lambda| of the Jacobian is
bounded by c + sqrt(k), the infinity norms of M^-1 C and M^-1 K with the nonlinear elements' tangents
(spectral_bound; the linear rows' part worked out once, linear_norms). A step whose h |lambda| passes
half the method's stability boundary is stability-limited. (Hairer's estimate from two stages at the
same time was tried first: on the book's quadratic damper it read h |lambda| = 33 where the eigenvalues
give 1.2, since the 1-DOF Jacobian [[0, 1], [-1000, -c]] is far from normal.)

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.kernels import tableaus as tb
from smdcli.kernels.arrays import CUBIC_SPRING
from smdcli.kernels.compiler import inlined, kernel, no_alloc
from smdcli.kernels.rhs import state_rhs, state_rhs_inlined

RK23, RK45, DOP853 = tb.RK23, tb.RK45, tb.DOP853
# How a run ended (index 0 of the status array).
OK, TOO_SMALL_STEP, STEP_BUDGET, NOT_FINITE, PAST_BOUND, STIFF = range(6)
# Counters (ints): right-hand sides, accepted, rejected, watched steps, stability-limited steps.
NFEV, ACCEPTED, REJECTED, WATCHED, LIMITED = range(5)
# Floats: time reached, largest h|lambda|, and where the watch stopped the run: time, share limited, h|lambda|.
T_REACHED, MAX_RHO, STIFF_T, STIFF_FRACTION, STIFF_RHO = range(5)

SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
# A reversal this close to a step's start is left inside it: its kink's error goes as the cube of that distance.
NEAR_START = 1e-3
WATCH_WINDOW, WATCH_LIMIT = 200, 0.8

_A = (tb.RK23_A, tb.RK45_A, tb.DOP853_A)
_B = (tb.RK23_B, tb.RK45_B, tb.DOP853_B)
_C = (tb.RK23_C, tb.RK45_C, tb.DOP853_C)
STAGES = (3, 6, tb.DOP853_STAGES)
ERROR_ORDER = (2, 4, 7)


@no_alloc
def rms(x):
    """Root mean square, scipy's error norm."""
    total = 0.0
    for v in x:
        total += v * v
    return math.sqrt(total / len(x)) if len(x) else 0.0


@inlined
def axpy(a, x, y):
    """y += a x, in place, without a temporary."""
    for i in range(len(y)):
        y[i] += a * x[i]


@inlined
def assign(dst, src):
    """dst[:] = src, element by element (a slice assignment would need the allocator)."""
    for i in range(len(dst)):
        dst[i] = src[i]


@no_alloc
def scaled_rms(x, scale):
    """rms(x / scale) without a temporary."""
    total = 0.0
    for i in range(len(x)):
        q = x[i] / scale[i]
        total += q * q
    return math.sqrt(total / len(x)) if len(x) else 0.0


@no_alloc
def state_status(y, bound):
    """OK, or why the state y counts as diverged: NOT_FINITE (NaN or inf) or PAST_BOUND (|y| > bound)."""
    status = OK
    for i in range(len(y)):
        if not math.isfinite(y[i]):
            return NOT_FINITE
        if abs(y[i]) > bound:
            status = PAST_BOUND
    return status


@no_alloc
def rows_through(grid, k, t):
    """The first row index at or after k whose grid time is past t: rows k..that-1 are due for output."""
    j = k
    while j < len(grid) and grid[j] <= t:
        j += 1
    return j


@no_alloc
def probe_step(d0, d1):
    """Hairer's first guess h0 at a first step, from the scaled sizes of the state (d0) and of its rate (d1)."""
    return 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1


@no_alloc
def probed_step(h0, d1, d2, order):
    """Hairer's first step from h0 and its Euler probe (d2: the rate's scaled change over h0, per unit of h0)."""
    if d1 <= 1e-15 and d2 <= 1e-15:
        return max(1e-6, h0 * 1e-3)
    return min(100 * h0, (0.01 / max(d1, d2)) ** (1.0 / (order + 1)))


@no_alloc
def initial_step(m, t0, y0, f0, t_bound, order, rtol, atol, mid, work, jwork, f1, y1, scale):
    """scipy's select_initial_step (Hairer, Norsett and Wanner, II.4); f1, y1 and scale are scratch."""
    length = t_bound - t0
    if length == 0.0:
        return 0.0
    for i in range(len(y0)):
        scale[i] = atol[i] + abs(y0[i]) * rtol
    d0 = scaled_rms(y0, scale)
    d1 = scaled_rms(f0, scale)
    h0 = min(probe_step(d0, d1), length)
    for i in range(len(y0)):
        y1[i] = y0[i] + h0 * f0[i]
    state_rhs(m, t0 + h0, y1, t0 + h0 >= mid, f1, work, jwork)
    for i in range(len(y0)):
        y1[i] = f1[i] - f0[i]
    return min(probed_step(h0, d1, scaled_rms(y1, scale) / h0, order), length)


@no_alloc
def _stages(m, method, t, y, h, K, count, mid, work, jwork, arg):
    """Stages 1..count-1 of a step into K (K[0] is f(t, y)); arg is scratch."""
    A, C = _A[method], _C[method]
    for s in range(1, count):
        assign(arg, y)
        for j in range(s):
            if A[s, j] != 0.0:
                axpy(h * A[s, j], K[j], arg)
        ts = t + C[s] * h
        state_rhs_inlined(m, ts, arg, ts >= mid, K[s], work, jwork)


@no_alloc
def _error_norm(method, K, h, scale, err, err3):
    """scipy's error norm of the step: the embedded pair's, or DOP853's blend of its 5th and 3rd order estimates."""
    S = STAGES[method]
    if method == DOP853:
        err[:] = 0.0
        err3[:] = 0.0
        for s in range(S + 1):
            axpy(tb.DOP853_E5[s], K[s], err)
            axpy(tb.DOP853_E3[s], K[s], err3)
        e5 = scaled_rms(err, scale) ** 2 * len(scale)
        e3 = scaled_rms(err3, scale) ** 2 * len(scale)
        if e5 == 0 and e3 == 0:
            return 0.0
        return abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * len(scale))
    E = tb.RK23_E if method == RK23 else tb.RK45_E
    err[:] = 0.0
    for s in range(S + 1):
        axpy(h * E[s], K[s], err)
    return scaled_rms(err, scale)


@no_alloc
def _dense(m, method, t_old, h, y_old, y_new, K, grid, k, j, out, mid, work, jwork, arg, F):
    """Rows k..j-1 of out from the step's interpolant (scipy's RkDenseOutput / Dop853DenseOutput)."""
    size = len(y_old)
    if method == DOP853:
        S = STAGES[method]
        for s in range(S + 1, 16):
            assign(arg, y_old)
            for i in range(s):
                if tb.DOP853_A[s, i] != 0.0:
                    axpy(h * tb.DOP853_A[s, i], K[i], arg)
            ts = t_old + tb.DOP853_C[s] * h
            state_rhs(m, ts, arg, ts >= mid, K[s], work, jwork)
        for i in range(size):
            delta = y_new[i] - y_old[i]
            F[0, i] = delta
            F[1, i] = h * K[0, i] - delta
            F[2, i] = 2 * delta - h * (K[S, i] + K[0, i])
        for r in range(4):
            F[3 + r] = 0.0
            for s in range(16):
                axpy(h * tb.DOP853_D[r, s], K[s], F[3 + r])
        for row in range(k, j):
            x = (grid[row] - t_old) / h
            for i in range(size):
                value = 0.0
                for q in range(7):
                    value += F[6 - q, i]
                    value *= x if q % 2 == 0 else 1 - x
                out[row, i] = value + y_old[i]
        return
    P = tb.RK23_P if method == RK23 else tb.RK45_P
    S = STAGES[method]
    for row in range(k, j):
        x = (grid[row] - t_old) / h
        assign(out[row], y_old)
        power = 1.0
        for q in range(P.shape[1]):
            power *= x
            for s in range(S + 1):
                if P[s, q] != 0.0:
                    axpy(h * P[s, q] * power, K[s], out[row])


@inlined
def relative(q, a, b, offset):
    """q[offset + a] - q[offset + b], ground (index -1) at zero."""
    return (q[offset + a] if a >= 0 else 0.0) - (q[offset + b] if b >= 0 else 0.0)


@no_alloc
def reversal(m, y, y_new, f, f_new, h):
    """Where in the step (a fraction of it) a quadratic damper's velocity first changes sign, or 1.0 for none: the
    root of the velocity's cubic Hermite interpolant (ends and accelerations), bracketed by bisection and
    returned at its far side, so that the step ends just past the reversal."""
    n = m.n
    first = 1.0
    for e in range(len(m.el_law)):
        if m.el_law[e] == CUBIC_SPRING:
            continue
        a, b = m.el_a[e], m.el_b[e]
        r0, r1 = relative(y, a, b, n), relative(y_new, a, b, n)
        if r0 * r1 >= 0.0:
            continue
        first = hermite_crossing(r0, r1, h * relative(f, a, b, n), h * relative(f_new, a, b, n), first)
    return first


@no_alloc
def hermite_crossing(r0, r1, d0, d1, first):
    """Where in [0, first] the cubic Hermite interpolant of a quantity (values r0, r1 at the step's ends, slopes d0,
    d1 over the step; a sign change within [0, first]) changes sign, bracketed by bisection and returned at its far
    side; from r0 = 0, the side it moves to is its slope's."""
    side = r0 if r0 != 0.0 else d0
    lo, hi = 0.0, first
    for _ in range(48):
        s = 0.5 * (lo + hi)
        u = 1.0 - s
        value = (r0 * (1 + 2 * s) + d0 * s) * u * u + (r1 * (3 - 2 * s) - d1 * u) * s * s
        if value * side > 0.0:
            lo = s
        else:
            hi = s
    return hi


@no_alloc
def attempt(m, method, t, y, h_abs, t_bound, mid, rtol, atol, fixed_h, K, y_new, scale, err, err3, arg, work, jwork,
            counts, land=False):
    """One accepted step from (t, y) with scipy's error control, from a first try of h_abs: (status, t_new, h,
    the next step's h_abs); y_new and K (K[S] = f(t_new, y_new)) hold the step; status TOO_SMALL_STEP where the
    step shrank below rounding. fixed_h > 0 takes that step without error control. land: a try in which a
    quadratic damper's velocity reverses is cut short to end just past the reversal (once a step), so that its
    kink (c |v| v has no second derivative at v = 0) falls between steps, not inside one, where it would cost
    rejected tries and shrunken steps."""
    S = STAGES[method]
    B = _B[method]
    exponent = -1.0 / (ERROR_ORDER[method] + 1)
    min_step = 10 * abs(np.nextafter(t, np.inf) - t)
    if h_abs < min_step:
        h_abs = min_step
    rejected = False
    landed = not land
    while True:
        if h_abs < min_step:
            return TOO_SMALL_STEP, t, 0.0, h_abs
        t_new = min(t + h_abs, t_bound)
        h = t_new - t
        h_abs = abs(h)
        _stages(m, method, t, y, h, K, S, mid, work, jwork, arg)
        assign(y_new, y)
        for s in range(S):
            if B[s] != 0.0:
                axpy(h * B[s], K[s], y_new)
        state_rhs(m, t_new, y_new, t_new >= mid, K[S], work, jwork)
        counts[NFEV] += S
        for i in range(len(y)):
            scale[i] = atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol
        if not landed:
            landed = True
            fraction = reversal(m, y, y_new, K[0], K[S], h)
            if NEAR_START < fraction < 1.0:
                h_abs *= fraction
                counts[REJECTED] += 1
                continue
        error = _error_norm(method, K, h, scale, err, err3)
        if fixed_h > 0:
            return OK, t_new, h, fixed_h
        if error < 1:
            factor = MAX_FACTOR if error == 0 else min(MAX_FACTOR, SAFETY * error ** exponent)
            if rejected:
                factor = min(1.0, factor)
            return OK, t_new, h, h_abs * factor
        h_abs *= max(MIN_FACTOR, SAFETY * error ** exponent)
        rejected = True
        counts[REJECTED] += 1


@kernel
def linear_norms(m):
    """spectral_bound's linear part, which a run computes once: (sums, rows). sums: each row's sums of |M^-1 K| and
    |M^-1 C| ([0:n] and [n:2n]) and their largest ([2n] and [2n + 1]); rows: those nonlinear elements' tangents can
    add to (the rows of M^-1 that reach a DOF an element joins)."""
    n = m.n
    joined = np.zeros(n, dtype=np.bool_)
    for e in range(len(m.el_law)):
        for dof in (m.el_a[e], m.el_b[e]):
            if dof >= 0:
                joined[dof] = True
    reached = np.zeros(n, dtype=np.bool_)
    sums = np.zeros(2 * n + 2)
    for i in range(n):
        for q in range(m.mi_ptr[i], m.mi_ptr[i + 1]):
            reached[i] = reached[i] or joined[m.mi_idx[q]]
        for q in range(m.a_ptr[i], m.a_ptr[i + 1]):
            sums[i + (n if m.a_idx[q] >= n else 0)] += abs(m.a_val[q])
    for i in range(n):
        sums[2 * n] = max(sums[2 * n], sums[i])
        sums[2 * n + 1] = max(sums[2 * n + 1], sums[n + i])
    return sums, np.nonzero(reached)[0]


@no_alloc
def spectral_bound(m, y, norms, node):
    """An upper bound on |lambda| of the Jacobian at y: |lambda|^2 <= c |lambda| + k gives |lambda| <= c + sqrt(k),
    with k and c the infinity norms of M^-1 Kt and M^-1 Ct (tangents included). norms: linear_norms'; a row's tangent
    only adds to its linear sum, so the largest row is the linear maximum's or one of the rows elements reach, and a
    call costs O(elements and their rows), not O(n) (the 1,000-mass chain's stiffness watch took 0.55 ms of its
    Taylor run). node is scratch of length 2n, zeros where no element joins: each DOF's tangent stiffness and damping
    from nonlinear elements, zeroed at the elements' DOFs before any is added to (elements share DOFs)."""
    n = m.n
    sums, rows = norms
    for e in range(len(m.el_law)):
        offset = 0 if m.el_law[e] == CUBIC_SPRING else n
        for dof in (m.el_a[e], m.el_b[e]):
            if dof >= 0:
                node[offset + dof] = 0.0
    for e in range(len(m.el_law)):
        a, b = m.el_a[e], m.el_b[e]
        offset = 0 if m.el_law[e] == CUBIC_SPRING else n
        d = (y[offset + a] if a >= 0 else 0.0) - (y[offset + b] if b >= 0 else 0.0)
        slope = 3 * m.el_coef[e] * d * d if m.el_law[e] == CUBIC_SPRING else 2 * m.el_coef[e] * abs(d)
        if a >= 0:
            node[offset + a] += 2 * slope
        if b >= 0:
            node[offset + b] += 2 * slope
    k = sums[2 * n]
    c = sums[2 * n + 1]
    for i in rows:
        row_k = sums[i]
        row_c = sums[n + i]
        for q in range(m.mi_ptr[i], m.mi_ptr[i + 1]):
            row_k += abs(m.mi_val[q]) * node[m.mi_idx[q]]
            row_c += abs(m.mi_val[q]) * node[n + m.mi_idx[q]]
        k = max(k, row_k)
        c = max(c, row_c)
    return c + math.sqrt(k)


@no_alloc
def held_by_stability(m, y, h, t, boundary, norms, node, ring, counts, floats):
    """The stiffness watch after a step of h to (t, y): record whether h |lambda| passed half the boundary, in the
    ring of the last WATCH_WINDOW steps and the counters; True (where it stopped, in floats) when WATCH_LIMIT of
    them did. norms and node are spectral_bound's (linear_norms, scratch)."""
    rho = h * spectral_bound(m, y, norms, node)
    floats[MAX_RHO] = max(floats[MAX_RHO], rho)
    limited = rho > 0.5 * boundary
    slot = counts[WATCHED] % WATCH_WINDOW
    counts[LIMITED] += limited
    counts[WATCHED] += 1
    ring[slot] = limited
    if counts[WATCHED] >= WATCH_WINDOW:
        fraction = np.sum(ring) / WATCH_WINDOW
        if fraction >= WATCH_LIMIT:
            floats[STIFF_T], floats[STIFF_FRACTION], floats[STIFF_RHO] = t, fraction, rho
            return True
    return False


@kernel
def integrate(m, method, y0, grid, cuts, rtol, atol, max_steps, bound, boundary, out, counts, floats, work, fixed_h,
              land):
    """Integrate from y0 = out[0] over the grid, restarting at each cut; returns a status (OK, ...).

    atol is per component; boundary > 0 turns on the stiffness watch (stop with STIFF when 80 % of the last
    200 steps are stability-limited). counts and floats receive the statistics named above; work is the
    right-hand side's scratch (rhs.work_size). fixed_h > 0 takes steps of that size with no error control
    (for measuring a formula's order); land ends steps at quadratic dampers' velocity reversals (attempt).
    """
    size = len(y0)
    S = STAGES[method]
    K = np.zeros((16, size))
    F = np.zeros((7, size))
    jwork = np.zeros((2 * m.n, 2 * m.n)) if size > 2 * m.n else np.zeros((1, 1))
    arg, err, err3 = np.zeros(size), np.zeros(size), np.zeros(size)
    y_new, scale, node = np.zeros(size), np.zeros(size), np.zeros(2 * m.n)
    norms = linear_norms(m)
    ring = np.zeros(WATCH_WINDOW, dtype=np.bool_)
    y = y0.copy()
    k = np.int64(1)  # not a literal 1: the row writers (_dense, _hermite) compile once, for any row
    floats[T_REACHED] = grid[0]
    for seg in range(len(cuts) - 1):
        ta, t_bound = cuts[seg], cuts[seg + 1]
        mid = 0.5 * (ta + t_bound)
        t = ta
        state_rhs(m, t, y, t >= mid, K[0], work, jwork)
        h_abs = fixed_h if fixed_h > 0 else initial_step(m, t, y, K[0], t_bound, ERROR_ORDER[method], rtol, atol,
                                                         mid, work, jwork, K[1], arg, scale)
        counts[NFEV] += 2
        while t < t_bound:
            status, t_new, h, h_abs = attempt(m, method, t, y, h_abs, t_bound, mid, rtol, atol, fixed_h, K, y_new,
                                              scale, err, err3, arg, work, jwork, counts, land)
            if status != OK:
                floats[T_REACHED] = t
                out[k:] = np.nan
                return status
            counts[ACCEPTED] += 1
            if counts[ACCEPTED] > max_steps:
                out[k:] = np.nan
                return STEP_BUDGET
            j = rows_through(grid, k, t_new)
            if j > k:
                _dense(m, method, t, h, y, y_new, K, grid, k, j, out, mid, work, jwork, arg, F)
                if method == DOP853:
                    counts[NFEV] += 3
                k = j
            floats[T_REACHED] = t_new
            status = state_status(y_new, bound)
            if status != OK:
                out[k:] = np.nan
                return status
            if boundary > 0 and held_by_stability(m, y_new, h, t_new, boundary, norms, node, ring, counts, floats):
                return STIFF
            t = t_new
            y[:] = y_new
            K[0] = K[S]
    return OK
