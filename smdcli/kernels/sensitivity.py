"""Compiled forward sensitivities of a smooth nonlinear scene: the state y = [x, v, q, energy] and its parameter
sensitivities S = dy/dp (over [x, v, q], one column per parameter) integrated together by Dormand-Prince 8(5,3),
the error controlled on both, every output time landed on.

S' = J(t, y) S + df/dp. J is analytic: the linear rows, the cubic springs' and quadratic dampers' tangents, the
smooth laws' tensions (Bouc-Wen's (1 - alpha) k z, regularized friction) and Bouc-Wen's internal rate. df/dp is
the right-hand side of the scene's models at each parameter's stencil points (models, weights and the parameter
each belongs to), as differences from the scene's own: exact where the parameter enters affinely.

J jumps where a Bouc-Wen element's d' or z changes sign (a kink of its rate): a step holds the branch of J it starts
on (branches), and a step that would cross such a kink is taken again to end KINK_MARGIN of itself past it, the
crossing found anew on each try's own interpolant, so that no step integrates S across a jump of J.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.elements.bouc_wen import SMOOTH_BOUC_WEN
from smdcli.elements.friction import SMOOTH_STRIBECK, SMOOTH_TANH
from smdcli.kernels import tableaus
from smdcli.kernels.arrays import CUBIC_SPRING
from smdcli.kernels.compiler import inlined, kernel, no_alloc
from smdcli.kernels.erk import (DOP853, ERROR_ORDER, MAX_FACTOR, MIN_FACTOR, NOT_FINITE, OK, SAFETY, STEP_BUDGET,
                                STIFF, TOO_SMALL_STEP, _error_norm, axpy, assign, hermite_crossing, probe_step,
                                probed_step, reversal, scaled_rms)
from smdcli.kernels.rhs import state_rhs, state_rhs_inlined

STAGES = tableaus.DOP853_STAGES
KINK_MARGIN = 1e-8  # how far past a kink (a fraction of the step) a step ends: past it for sure, its branch held
LANDINGS = 12  # tries a step may take to end just past a kink (each found on the last try's interpolant)
CROSSING_SAMPLES = 8  # points of a step's interpolant a kink's quantity is looked at (its end among them)
A, B, C = tableaus.DOP853_A, tableaus.DOP853_B, tableaus.DOP853_C
LAST_STAGE = 11  # DOP853's stage at the step's end (c = 1), beside whose rate the end's measures h |lambda|
# Hairer's stiffness test of DOP853 (dop853.f): h |lambda| past STIFF_RHO (6.1, its stability boundary's) in
# STIFF_STEPS accepted steps with fewer than NONSTIFF_STEPS others between them says the steps are stability's, not
# accuracy's: a run stops (STIFF) where they are also below OUTPUT_SHARE of the output step, so that Radau, whose
# steps cost ten of these and land on every output time, takes fewer than a tenth as many (REGULARIZED's friction
# over 3 s at rtol 1e-9: at r = 1e-3 and 1e-4 m/s, stability-limited to an eighth and a thirteenth of the output
# step, DOP853 took 57 and 84 ms, Radau 152 and 157; at 1e-5, a 130th, 228 ms and 157)
STIFF_RHO, STIFF_STEPS, NONSTIFF_STEPS, OUTPUT_SHARE = 6.1, 15, 6, 1e-2


@no_alloc
def frozen_partials(p, z, rate, sign_rate, sign_z):
    """Bouc-Wen's (d z_rate / d z, d z_rate / d d') with |d'| and |z| read on the sides sign_rate and sign_z: the
    branch a step keeps from its start, so that J has no jump inside it (rhs.bouc_wen_partials, signs given)."""
    size = max(sign_z * z, 0.0)  # a step's last 1e-8 may lie past the kink, where the held branch's |z| is 0
    power = size ** (p[4] - 1) if size > 0 or p[4] > 1 else 1.0
    by_z = -p[2] * sign_rate * rate * p[4] * power - p[3] * rate * p[4] * power * sign_z
    by_rate = p[1] - p[2] * sign_rate * power * z - p[3] * size ** p[4]
    return by_z, by_rate


@no_alloc
def branches(m, y, f, signs):
    """Each Bouc-Wen element's side of its two kinks at (y, f): the signs of its rate and of its z, where one is
    zero the sign it moves to (its own rate's), as the step from y keeps them."""
    n = m.n
    for e in range(len(m.ns_belt)):
        if m.ns_law[e] != SMOOTH_BOUC_WEN:
            continue
        rate, slope = m.ns_belt[e], 0.0
        for i in range(n):
            rate += m.ns_R[e, i] * y[n + i]
            slope += m.ns_R[e, i] * f[n + i]
        z = 2 * n + int(m.ns_par[e, 5])
        signs[e, 0] = 1.0 if rate > 0 or rate == 0 and slope >= 0 else -1.0
        signs[e, 1] = 1.0 if y[z] > 0 or y[z] == 0 and f[z] >= 0 else -1.0


@inlined
def exact_jacobian(m, y, J, dwork, signs):
    """J = d rhs / d [x, v, q] at y (s x s, s = 2n + q), analytic, each Bouc-Wen element on the side of its kinks
    that signs (E, 2: of its rate, of its z) holds for the step; dwork (n, s) is scratch for the forces' rows."""
    n = m.n
    s = 2 * n + m.ns_q
    for i in range(s):
        for c in range(s):
            J[i, c] = 0.0
    for i in range(n):
        for c in range(s):
            dwork[i, c] = 0.0
        J[i, n + i] = 1.0
        for k in range(m.a_ptr[i], m.a_ptr[i + 1]):
            J[n + i, m.a_idx[k]] += m.a_val[k]
    for e in range(len(m.el_law)):  # work[a] -= g(d), work[b] += g(d), d = y[a] - y[b] (of x or of v)
        a, b = m.el_a[e], m.el_b[e]
        offset = 0 if m.el_law[e] == CUBIC_SPRING else n
        d = (y[offset + a] if a >= 0 else 0.0) - (y[offset + b] if b >= 0 else 0.0)
        slope = 3 * m.el_coef[e] * d * d if m.el_law[e] == CUBIC_SPRING else 2 * m.el_coef[e] * abs(d)
        for node, sign in ((a, -1.0), (b, 1.0)):
            if node < 0:
                continue
            if a >= 0:
                dwork[node, offset + a] += sign * slope
            if b >= 0:
                dwork[node, offset + b] -= sign * slope
    for e in range(len(m.ns_belt)):  # work[i] -= T_e R_ei for each free element's smooth tension T_e
        if m.ns_held[e]:
            continue
        p = m.ns_par[e]
        rate = m.ns_belt[e]
        for i in range(n):
            rate += m.ns_R[e, i] * y[n + i]
        law = m.ns_law[e]
        by_rate = 0.0
        if law == SMOOTH_BOUC_WEN:
            col = 2 * n + int(p[5])
            for i in range(n):
                dwork[i, col] -= m.ns_R[e, i] * p[0]
            z_by_z, z_by_rate = frozen_partials(p, y[col], rate, signs[e, 0], signs[e, 1])
            J[col, col] += z_by_z
            for i in range(n):
                J[col, n + i] += z_by_rate * m.ns_R[e, i]
        elif law == SMOOTH_STRIBECK:
            by_rate = p[0] * (p[2] - p[1]) * math.exp(-(rate / p[3]) ** 2) * (-2.0 * rate / (p[3] * p[3]))
        elif law == SMOOTH_TANH:
            th = math.tanh(rate / p[1])
            by_rate = p[0] * (1.0 - th * th) / p[1]
        if by_rate != 0.0:
            for i in range(n):
                for c in range(n):
                    dwork[i, n + c] -= m.ns_R[e, i] * by_rate * m.ns_R[e, c]
    for i in range(n):  # the accelerations: M^-1 (as the mode projects it) of the forces' rows
        for kk in range(m.mi_ptr[i], m.mi_ptr[i + 1]):
            w = m.mi_val[kk]
            for c in range(s):
                J[n + i, c] += w * dwork[m.mi_idx[kk], c]


@no_alloc
def kink(m, y, y_new, f, f_new, h):
    """Where in the step (a fraction of it) a law's right-hand side first has a kink, or 1.0 for none: a quadratic
    damper's velocity (erk.reversal), a Bouc-Wen element's rate or its z changing sign; found on the cubic Hermite
    interpolant, returned just past it, so that the step ends there and the kink falls between steps."""
    n = m.n
    first = reversal(m, y, y_new, f, f_new, h)
    for e in range(len(m.ns_belt)):
        if m.ns_law[e] != SMOOTH_BOUC_WEN or m.ns_held[e]:
            continue
        r0, r1, d0, d1 = m.ns_belt[e], m.ns_belt[e], 0.0, 0.0
        for i in range(n):
            r0 += m.ns_R[e, i] * y[n + i]
            r1 += m.ns_R[e, i] * y_new[n + i]
            d0 += h * m.ns_R[e, i] * f[n + i]
            d1 += h * m.ns_R[e, i] * f_new[n + i]
        first = first_crossing(r0, r1, d0, d1, first)
        z = 2 * n + int(m.ns_par[e, 5])
        first = first_crossing(y[z], y_new[z], h * f[z], h * f_new[z], first)
    return first


@no_alloc
def stability_limited(y, y_new, K, h, scratch, stiff_rho):
    """Hairer's test after a step of h from y to y_new: h |lambda| ~ h |f(y_new) - f(y_12)| / |y_new - y_12|, y_12
    the last stage's point (the same time), past stiff_rho."""
    assign(scratch, y)
    for j in range(LAST_STAGE):
        if A[LAST_STAGE, j] != 0.0:
            axpy(h * A[LAST_STAGE, j], K[j], scratch)
    rates, points = 0.0, 0.0
    for i in range(len(y)):
        rates += (K[STAGES, i] - K[LAST_STAGE, i]) ** 2
        points += (y_new[i] - scratch[i]) ** 2
    return points > 0.0 and abs(h) * math.sqrt(rates / points) > stiff_rho


@no_alloc
def kink_landing(m, y, y_new, f, f_new, h, landed, min_step):
    """The step to take again where a law's kink lies inside this one (J jumps there: the step ends just past it, on
    the branch it started on, each try's crossing, found on its own shorter interpolant, nearer the end, until it is
    at the end), or 0.0 where none does or the step has been landed LANDINGS times."""
    at = kink(m, y, y_new, f, f_new, h)
    if at < 1.0 - 2 * KINK_MARGIN and landed < LANDINGS:
        return max(abs(h) * (at + KINK_MARGIN), 2 * min_step)
    return 0.0


@no_alloc
def first_crossing(r0, r1, d0, d1, first):
    """Where in [0, first] the cubic Hermite interpolant of a quantity (values r0, r1 at the step's ends, slopes d0,
    d1 over the step) first changes sign, just past it, or first for none: looked at in CROSSING_SAMPLES points, so
    that one crossing and coming back within the step (a grazing d' or z: its held branch would be wrong between,
    unseen by the error estimate) is found too, then bisected (erk.hermite_crossing)."""
    # on the kink at the start, branches took the side it moves to, its slope's: a step that turns back across it
    # is cut there too (a first step of Hairer's length from a mass leaving a stop, d' = 0, held the wrong branch of a
    # Bouc-Wen law's J past its turn: 1.1e-5 off)
    side = r0 if r0 != 0.0 else d0
    if side == 0.0:
        return first
    for j in range(1, CROSSING_SAMPLES + 1):
        s = first * j / CROSSING_SAMPLES
        u = 1.0 - s
        if ((r0 * (1 + 2 * s) + d0 * s) * u * u + (r1 * (3 - 2 * s) - d1 * u) * s * s) * side < 0.0:
            return hermite_crossing(r0, r1, d0, d1, s)
    return first


@inlined
def augmented_rates(m, models, weights, owner, ratios, moves, g, t, y, left, dy, work, J, dwork, f, signs):
    """dy = [f(t, y); J S + df/dp] for y = [state; S row-major (s, P)], J on the sides `signs` holds (branches);
    models: the stencil's first len(weights) of a padded tuple (compiler.model_tuple); where moves[j], model j
    moves M and its accelerations' difference from the scene's enters as M^-1 M_j (a_j - a) (ratios[j] = M^-1 M_j:
    the stencil's combination is then M^-1 (dF/dp - dM/dp a), the forces' stencil, not the accelerations'); f, J,
    dwork and g (n) are scratch.
    Inlined (numba's inliner, not LLVM's) at one call site of _march, which numba compiles without reference
    counting: counted, every read of a model's arrays cost an atomic increment and decrement; called, it was handed
    the stencil's models array by array at every stage (as numba loads a kernel from its cache nothing is inlined
    across libraries). The scene's and the stencil's right-hand sides are one inlined copy, the model chosen by j."""
    n = m.n
    size = 2 * n + m.ns_q + m.ns_acc
    s = 2 * n + m.ns_q
    P = (len(y) - size) // s
    for j in range(-1, len(weights)):  # the scene's model, then the stencil's: one inlined right-hand side for all
        model = m if j < 0 else models[j]
        state_rhs_inlined(model, t, y[:size], left, f, work, J)  # J is untouched at this length
        if j < 0:
            assign(dy[:size], f)
            if P == 0:
                return  # the state alone (the first pass that sets the tolerances): no J
            exact_jacobian(m, y, J, dwork, signs)
            for i in range(s):
                for p in range(P):
                    total = 0.0
                    for c in range(s):
                        if J[i, c] != 0.0:
                            total += J[i, c] * y[size + c * P + p]
                    dy[size + i * P + p] = total
            continue
        p, w = owner[j], weights[j]
        if moves[j]:
            for i in range(n):
                g[i] = f[n + i] - dy[n + i]
            for i in range(n):
                total = 0.0
                for c in range(n):
                    total += ratios[j, i, c] * g[c]
                f[n + i] = dy[n + i] + total
        for i in range(s):
            dy[size + i * P + p] += w * (f[i] - dy[i])


@kernel
def integrate(m, models, weights, owner, ratios, moves, y0, grid, cuts, rtol, atol, max_steps, out, rates, work,
              counts, reached, stiff_rho):
    """From y0 at grid[0] over the grid, restarting at each cut (a force's discontinuity) as the compiled pairs do,
    each output time landed on: out and rates (N, len(y0)) get the state and its rate there (right limits); counts:
    right-hand sides, accepted and rejected steps; reached[0]: the time a failure met. Returns OK, TOO_SMALL_STEP,
    STEP_BUDGET, NOT_FINITE or STIFF (Hairer's test, h |lambda| past stiff_rho (inf: never): the scene is for
    kernels.implicit_sensitivity)."""
    size_all = len(y0)
    n = m.n
    s = 2 * n + m.ns_q
    K = np.zeros((STAGES + 1, size_all))
    arg, y_new, scale = np.zeros(size_all), np.zeros(size_all), np.zeros(size_all)
    err, err3 = np.zeros(size_all), np.zeros(size_all)
    J, dwork, f, g = np.zeros((s, s)), np.zeros((n, s)), np.zeros(2 * n + m.ns_q + m.ns_acc), np.zeros(n)
    signs, now = np.ones((len(m.ns_belt), 2)), np.ones((len(m.ns_belt), 2))
    return _march(m, models, weights, owner, ratios, moves, y0.copy(), grid, cuts, rtol, atol, max_steps, out, rates,
                  work, counts, reached, K, arg, y_new, scale, err, err3, J, dwork, f, g, signs, now, stiff_rho)


@no_alloc
def _march(m, models, weights, owner, ratios, moves, y, grid, cuts, rtol, atol, max_steps, out, rates, work, counts,
           reached, K, arg, y_new, scale, err, err3, J, dwork, f, g, signs, now, stiff_rho):
    """integrate's steps, on the scratch it made: compiled without reference counting, which the stages' inlined
    right-hand sides would otherwise pay on every read of a model's arrays. The stages have one call site, inlined
    (a call handed over the stencil's models, array by array, and took a third of the time): a step's first stage is
    taken anew (fresh) at a segment's start and past a kink, as a pass of the stage loop that takes no step, and an
    output's rate wanted at a cut (pending) is the next segment's first (at the last cut: one more segment, empty);
    the first step's length is Hairer's (erk.initial_step's), its Euler probe one more such pass (probing)."""
    size_all = len(y)
    size = 2 * m.n + m.ns_q + m.ns_acc
    assign(out[0], y)
    state_rhs(m, grid[0], y[:size], np.bool_(False), K[0][:size], work, J)  # the state's rates say the branches
    branches(m, y, K[0], signs)
    pending = 0  # rates[0]: the first segment's first stage
    k = np.int64(1)  # not a literal 1: the row writers (_dense, _hermite) compile once, for any row
    exponent = -1.0 / 8.0
    h_abs = 0.0
    probing = False
    d1 = 0.0
    stiff_steps, other_steps = 0, 0
    for seg in range(len(cuts)):
        ta = cuts[seg]
        t_end = cuts[seg + 1] if seg + 1 < len(cuts) else ta
        mid = 0.5 * (ta + t_end) if seg + 1 < len(cuts) else np.inf  # the empty last one: the end's right limit
        t = ta
        fresh = True
        while t < t_end or fresh:
            target = grid[k] if k < len(grid) and grid[k] < t_end else t_end
            min_step = 10 * abs(np.nextafter(t, np.inf) - t)
            rejected = False
            landed = np.int64(0)  # not a literal: kink_landing compiles once
            while True:
                if not fresh and not probing and h_abs < min_step:
                    reached[0] = t
                    return TOO_SMALL_STEP
                t_new = t if fresh else min(t + h_abs, target)
                h = t_new - t
                for st in range(0 if fresh else 1, 1 if fresh else 2 if probing else STAGES + 1):
                    assign(arg, y)
                    ts = t
                    if probing:  # the first step's Euler probe: f(t + h0, y + h0 f) into K[1]
                        ts = t + h_abs
                        axpy(h_abs, K[0], arg)
                    elif st == STAGES:  # the step's end (y_new), whose rate starts the next step
                        ts = t_new
                        for j in range(STAGES):
                            if B[j] != 0.0:
                                axpy(h * B[j], K[j], arg)
                    elif st > 0:
                        ts = t + C[st] * h
                        for j in range(st):
                            if A[st, j] != 0.0:
                                axpy(h * A[st, j], K[j], arg)
                    augmented_rates(m, models, weights, owner, ratios, moves, g, ts, arg, ts >= mid, K[st], work, J,
                                    dwork, f, signs)
                if fresh:
                    fresh = False
                    counts[0] += 1
                    if pending >= 0:
                        assign(rates[pending], K[0])
                        pending = -1
                    if t >= t_end:
                        break
                    if h_abs == 0.0:  # later segments go on at the pace the first reached: a force's kink needs none
                        for i in range(size_all):
                            scale[i] = atol[i] + abs(y[i]) * rtol
                        d0, d1 = scaled_rms(y, scale), scaled_rms(K[0], scale)
                        # h0 alone took 1e-16 s where the state was rounding's (a Stribeck contact just broken away,
                        # its chain at 1e-17 m) and the sensitivities' rates whole: no step could be taken
                        h_abs = min(probe_step(d0, d1), t_end - t)
                        probing = True
                    continue
                if probing:
                    probing = False
                    counts[0] += 1
                    for i in range(size_all):
                        err[i] = K[1][i] - K[0][i]
                    d2 = scaled_rms(err, scale) / h_abs
                    h_abs = min(probed_step(h_abs, d1, d2, np.int64(ERROR_ORDER[DOP853])), t_end - t)
                    continue
                assign(y_new, arg)
                counts[0] += STAGES
                again = kink_landing(m, y, y_new, K[0], K[STAGES], h, landed, min_step)
                if again > 0.0:
                    landed += 1
                    h_abs = again
                    counts[2] += 1
                    continue
                for i in range(size_all):
                    scale[i] = atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol
                error = _error_norm(np.int64(DOP853), K, h, scale, err, err3)
                if error < 1:
                    factor = MAX_FACTOR if error == 0 else min(MAX_FACTOR, SAFETY * error ** exponent)
                    if rejected:
                        factor = min(1.0, factor)
                    if t_new < target or h >= h_abs:  # a step cut short to land sets no pace for the next
                        h_abs = abs(h) * factor
                    break
                h_abs = abs(h) * max(MIN_FACTOR, SAFETY * error ** exponent)
                rejected = True
                counts[2] += 1
            if t >= t_end:
                break  # the last cut's lone first stage: no step
            counts[1] += 1
            reached[0] = t
            if counts[1] > max_steps:
                return STEP_BUDGET
            for i in range(size_all):
                if not math.isfinite(y_new[i]):
                    return NOT_FINITE
            last = min(k, len(grid) - 1)
            if abs(h) < OUTPUT_SHARE * (grid[last] - grid[last - 1]) and stability_limited(y, y_new, K, h, err,
                                                                                          stiff_rho):
                stiff_steps, other_steps = stiff_steps + 1, 0
                if stiff_steps == STIFF_STEPS:
                    return STIFF
            else:
                other_steps += 1
                if other_steps == NONSTIFF_STEPS:
                    stiff_steps = 0
            t = t_new
            assign(y, y_new)
            assign(K[0], K[STAGES])
            branches(m, y, K[0], now)
            for e in range(len(now)):
                if now[e, 0] != signs[e, 0] or now[e, 1] != signs[e, 1]:
                    fresh = t < t_end  # a kink crossed: the next step's branch, its first stage again (a cut's anyway)
                signs[e, 0], signs[e, 1] = now[e, 0], now[e, 1]
            if k < len(grid) and t == grid[k]:
                assign(out[k], y)
                if fresh or t >= t_end:  # a new branch's rate; at a cut the right limit, where the step took the left
                    pending = k
                else:  # inside a segment the force's two limits are one
                    assign(rates[k], K[0])
                k += 1
    return OK
