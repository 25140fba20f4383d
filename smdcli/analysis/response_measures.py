"""The measures `smd optimize` minimizes, each with its exact gradient in the parameters: of a linear scene a
receptance's or a transmissibility's located peaks (the H-infinity norm) and the RMS under white noise (the H2
norm, by Lyapunov); of any scene's run its peaks, drifts, accelerations, residual displacement and the
energy an element dissipates (analysis/dissipation) (from its sensitivities).

derived: per parameter (dM, dC, dK), the model's derivatives (model_derivative's). Must not import: io, plots,
commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.analysis.dissipation import dissipated
from smdcli.errors import ScenarioError, UsageError

GRID_POINTS = 400  # frequencies a receptance is first sampled at: its peaks then located to rounding between them
EPS = float(np.finfo(float).eps)
GROUND = -2  # a drift measured from the ground: x_a itself


def dynamic_stiffness(M, C, K, w: float) -> np.ndarray:
    """Z(w) = K - w^2 M + i w C."""
    return K - w * w * M + 1j * w * C


def receptance_peaks(M, C, K, input_dof: int, dof: int, derived) -> np.ndarray:
    """Every local maximum of |H_dof(w)| = |x_dof / F| for a unit force on input_dof (frequency_peaks)."""
    return frequency_peaks(M, C, K, dof, derived, input_dof)


def transmissibility_peaks(M, C, K, dof: int, derived) -> np.ndarray:
    """Every local maximum of |T_dof(w)|, the absolute acceleration (or displacement) of dof per the ground's, under
    support motion: T = 1 + Y with Z Y = w^2 M 1 (frequency_peaks)."""
    return frequency_peaks(M, C, K, dof, derived, None)


def frequency_peaks(M, C, K, dof: int, derived, input_dof: int | None) -> np.ndarray:
    """Every local maximum over w >= 0 of |R_dof(w)|, R = offset + Z^-1 r(w): a receptance (r = the unit force on
    input_dof, offset 0) or, with input_dof None, a transmissibility (r = w^2 M 1, offset 1). Rows (w, |R|,
    d|R|/dp...): each located as the zero of d|R|^2/dw between neighbours of a grid over the modes (w = 0 where |R|
    falls from it), its derivative at the peak's fixed frequency (the envelope theorem: dR/dp = Z^-1 (dr/dp -
    dZ/dp Y), Y = Z^-1 r)."""
    n = len(M)
    support = input_dof is None
    ones = np.ones(n)
    force = np.zeros(n, complex)
    if not support:
        force[input_dof] = 1.0
    offset = 1.0 if support else 0.0
    squared = np.linalg.eigvals(np.linalg.solve(M, K)).real
    top = math.sqrt(max(float(squared.max(initial=0.0)), 0.0)) or 1.0
    grid = np.concatenate([[0.0], np.geomspace(1e-3 * top, 3.0 * top, GRID_POINTS)])

    def load(w):  # r(w) and dr/dw, (..., n) for an array of frequencies
        w = np.asarray(w, dtype=float)[..., None]
        if support:
            return (w**2 * (M @ ones)).astype(complex), 2 * w * (M @ ones)
        return np.broadcast_to(force, w.shape[:-1] + (n,)), np.zeros(w.shape[:-1] + (n,))

    def slopes_at(ws):  # d|R_dof|^2 / dw at each of ws at once (sweep.frequency.amplitude_slope's, vectorized)
        W = np.asarray(ws, dtype=float)[:, None, None]
        Z = K[None] - W**2 * M[None] + 1j * W * C[None]
        r, dr = load(ws)
        Y = np.linalg.solve(Z, r[..., None])
        dY = np.linalg.solve(Z, dr[..., None] - (-2 * W * M[None] + 1j * C[None]) @ Y)
        return 2.0 * (np.conj(offset + Y[:, dof, 0]) * dY[:, dof, 0]).real

    slopes = slopes_at(grid)  # every grid frequency at once
    located = [0.0] if slopes[1] < 0 else []
    falls = np.flatnonzero((slopes[:-1] > 0) & (slopes[1:] <= 0))
    located += list(_falling_zeros(slopes_at, grid[falls], grid[falls + 1], slopes[falls], slopes[falls + 1],
                                   1e-15 * top))
    if slopes[-1] > 0:  # still rising at 3 times the highest mode: a massless DOF or a rigid input; take the end
        located.append(float(grid[-1]))
    rows = []
    for w in located:
        Z = dynamic_stiffness(M, C, K, w)
        Y = np.linalg.solve(Z, load(w)[0])
        R = offset + Y[dof]
        size = abs(R)
        row = [w, size]
        for dM, dC, dK in derived:
            dr = w * w * (dM @ ones) if support else np.zeros(n)
            dY = np.linalg.solve(Z, dr - dynamic_stiffness(dM, dC, dK, w) @ Y)
            row.append(float((np.conj(R) * dY[dof]).real) / size if size else 0.0)
        rows.append(row)
    return np.array(rows, dtype=float).reshape(len(rows), 2 + len(derived))


def _falling_zeros(slope, low: np.ndarray, high: np.ndarray, f_low: np.ndarray, f_high: np.ndarray,
                   xtol: float) -> np.ndarray:
    """The zero of slope (vectorized over an array of points) in each bracket (low, high] where it falls from
    f_low > 0 to f_high <= 0, all brackets at once: the Illinois method (regula falsi, the end that stays has its
    value halved), to xtol plus 4 eps of the zero, as Brent's method to the same tolerance."""
    a, b, fa, fb = (np.array(q, dtype=float) for q in (low, high, f_low, f_high))
    done = fb == 0
    for _ in range(200):
        if done.all():
            break
        c = np.where(done, b, (a * fb - b * fa) / np.where(fb != fa, fb - fa, 1.0))
        c = np.clip(c, np.minimum(a, b), np.maximum(a, b))
        fc = np.where(done, 0.0, slope(c))
        flip = np.sign(fc) != np.sign(fb)
        a, fa = np.where(flip, b, a), np.where(flip, fb, fa * 0.5)
        b, fb = c, fc
        done |= (fc == 0) | (np.abs(b - a) <= xtol + 4 * EPS * np.abs(c))  # the bracket itself that small
    return b


def rms(M, C, K, input_dof: int | None, dof: int, derived, other: int | None = None, acceleration: bool = False,
        profile=None) -> tuple[float, np.ndarray]:
    """The RMS of x_dof (of the drift x_dof - x_other, or with `acceleration` of the absolute acceleration) and its
    gradient, under a one-sided input PSD: a force on input_dof (N^2/Hz) or, input_dof None, the support's
    acceleration ((m/s^2)^2/Hz). White noise of level 1 by Lyapunov, A Sigma + Sigma A^T + B B^T / 2 = 0 and the
    same differentiated; a profile (random_vibration.Profile, SI) by quadrature of |H|^2 S and of its derivative
    2 Re(conj(H) dH/dp) S, the natural frequencies as break points."""
    n = len(M)
    Minv = np.linalg.inv(M)
    support = input_dof is None

    def system(d=None):  # (A, B, L, D) of z' = A z + B u, q = L z + D u; or their derivatives along d = (dMi, dC, dK)
        A = np.zeros((2 * n, 2 * n))
        B, L = np.zeros(2 * n), np.zeros(2 * n)
        inverse = Minv if d is None else d[0]
        stiffness = -(Minv @ K if d is None else d[0] @ K + Minv @ d[2])
        damping = -(Minv @ C if d is None else d[0] @ C + Minv @ d[1])
        A[n:, :n], A[n:, n:] = stiffness, damping
        if d is None:
            A[:n, n:] = np.eye(n)
        if not support:
            B[n:] = inverse[:, input_dof]
        elif d is None:
            B[n:] = -1.0  # relative coordinates: x'' = ... - a_g
        if acceleration:  # x'' + a_g under support motion (no feedthrough); x'' = ... + M^-1 F under a force
            L[:n], L[n:] = stiffness[dof], damping[dof]
        elif d is None:
            L[dof] = 1.0
            if other is not None and other >= 0:
                L[other] -= 1.0
        return A, B, L, 0.0 if support or not acceleration else float(inverse[dof, input_dof])

    A, B, L, D = system()
    steps = [system((-Minv @ dM @ Minv, dC, dK)) for dM, dC, dK in derived]
    if profile is None:
        if D != 0.0:
            raise UsageError("the acceleration of a mass the force acts on directly has infinite "
                             "variance under white noise (its receptance does not fall with frequency); give a "
                             "band-limited PSD (--input-psd FILE)")
        variance, gradient = _white_noise(A, B, L, steps)
    else:
        variance, gradient = _profile_noise(A, B, L, D, steps, profile, M, K)
    if not variance > 0 or not np.isfinite(variance):
        raise ScenarioError("", "damping", "the RMS response to white noise is unbounded: the scene needs damping in "
                            "every mode its input reaches")
    value = math.sqrt(variance)
    return value, np.asarray(gradient) / (2 * value)


def _white_noise(A, B, L, steps) -> tuple[float, list[float]]:
    """L Sigma L^T and its derivatives along steps ((dA, dB, dL, dD) each) by the Lyapunov equation and its twin."""
    from scipy.linalg import solve_continuous_lyapunov

    Sigma = solve_continuous_lyapunov(A, -0.5 * np.outer(B, B))
    gradient = []
    for dA, dB, dL, _ in steps:
        rhs = dA @ Sigma + Sigma @ dA.T + 0.5 * (np.outer(dB, B) + np.outer(B, dB))
        dSigma = solve_continuous_lyapunov(A, -rhs)
        gradient.append(float(L @ dSigma @ L + 2 * dL @ Sigma @ L))
    return float(L @ Sigma @ L), gradient


def _profile_noise(A, B, L, D, steps, profile, M, K) -> tuple[float, np.ndarray]:
    """The integral over the profile of |H|^2 S and of 2 Re(conj(H) dH/dp) S, H = L (i w - A)^-1 B + D, each
    segment by quad_vec to 1e-12 relative with the natural frequencies inside it as break points."""
    from scipy.integrate import quad_vec

    natural_hz = np.sqrt(np.maximum(np.linalg.eigvals(np.linalg.solve(M, K)).real, 0.0)) / (2 * math.pi)
    eye = np.eye(len(A))

    def integrand(f):
        resolvent = 2j * math.pi * f * eye - A
        z = np.linalg.solve(resolvent, B)
        H = L @ z + D
        row = [abs(H) ** 2]
        for dA, dB, dL, dD in steps:
            dz = np.linalg.solve(resolvent, dA @ z + dB)
            row.append(2.0 * (np.conj(H) * (dL @ z + L @ dz + dD)).real)
        return np.array(row) * profile(np.array([f]))[0]

    total = np.zeros(1 + len(steps))
    for f0, f1, _, _ in profile.segments():
        inside = [float(f) for f in natural_hz if f0 < f < f1]
        value, _ = quad_vec(integrand, f0, f1, epsrel=1e-12, epsabs=0.0, points=inside or None, limit=10_000)
        total += value
    return float(total[0]), total[1:]


TIME_PEAKS = 8  # a largest peak in time minimized as the minimax over this many of its run's largest local peaks


def time_measure(s, measure) -> tuple[float, np.ndarray, np.ndarray | None]:
    """A time-domain measure of a run, its gradient from the run's sensitivities s, and the smooth pieces of a largest
    peak: the located peak of |x| or of a drift |x_a - x_b| with rows (time, |peak|, d|peak|/dp...) of the run's
    TIME_PEAKS largest local peaks in time (each one's derivative at its own time, the envelope theorem: the
    largest is their maximum, minimized as such); the largest sampled |a| (absolute under support motion: relative
    plus the ground's), located and in pieces the same way on a linear scene; |x| at the run's end; the energy a
    damper dissipates."""
    from smdcli.solvers.peaks import local_peaks, quintic_at

    j, kind = measure.dof, measure.kind
    if kind == "residual_displacement":
        x = float(s.displacement[-1, j])
        return abs(x), np.sign(x) * s.d_displacement[:, -1, j], None
    if kind == "peak_acceleration":
        return _peak_acceleration(s, j)
    if kind == "dissipated":
        return (*dissipated(s, measure.element), None)
    k = measure.other if kind == "peak_drift" else GROUND

    def drift(q):  # (..., N, n) -> (..., N): x_j, or the drift x_j - x_k
        return q[..., j] - (q[..., k] if k != GROUND else 0.0)
    series = [drift(q) for q in (s.displacement, s.velocity, s.acceleration)]
    values, times = local_peaks(s.time, *series, s.event_times, TIME_PEAKS)
    signs = np.sign(quintic_at(s.time, *series, times))
    if s.exact_at is not None:  # on the exact flow at each peak's time
        derivative = np.array([drift(s.exact_at(float(t))) for t in times]).reshape(len(times), -1)
    else:
        derived = [drift(q) for q in (s.d_displacement, s.d_velocity, s.d_acceleration)]
        derivative = np.array([quintic_at(s.time, derived[0][p], derived[1][p], derived[2][p], times)
                               for p in range(len(s.parameter))]).T.reshape(len(times), -1)
    rows = np.column_stack([times, values, signs[:, None] * derivative])
    return float(values[0]), rows[0, 2:].copy(), rows


def _peak_acceleration(s, j: int) -> tuple[float, np.ndarray, np.ndarray]:
    """The largest |absolute acceleration| of DOF j with its pieces (time_measure's rows): on a linear scene each of
    the run's largest local peaks located between samples on the quintic Hermite of a, a', a'' (the model's own
    equation differentiated, acceleration_rates) and its derivative on the sensitivities' same quintic; elsewhere
    the samples' local maxima."""
    from smdcli.solvers.peaks import local_peaks, quintic_at

    if s.exact_rates_at is not None or s.dense_acceleration_at is not None:
        located = _peaks_on_flow(s, j) if s.exact_rates_at is not None else _peaks_on_dense(s, j)
        if located is not None:
            return float(located[0, 1]), located[0, 2:].copy(), located
    rates = acceleration_rates(s)
    if rates is None:
        a, da = s.acceleration[:, j].copy(), s.d_acceleration[:, :, j].copy()
        ground = s.ground_acceleration()
        if ground is not None:
            a, da = a + ground[0], da + ground[1]
        values, times = local_peaks(s.time, a, None, None, count=TIME_PEAKS)
        k = np.searchsorted(s.time, times)
        derivative = (np.sign(a[k])[None] * da[:, k]).T
    else:
        a, right, snap, left, snap_left, kinks = rates
        events = np.concatenate([s.event_times, kinks])
        values, times = local_peaks(s.time, a[0, :, j], right[0, :, j], snap[0, :, j], events, TIME_PEAKS,
                                    left[0, :, j], snap_left[0, :, j])
        signs = np.sign(quintic_at(s.time, a[0, :, j], right[0, :, j], snap[0, :, j], times, left[0, :, j],
                                   snap_left[0, :, j]))
        derivative = np.array([signs * quintic_at(s.time, a[p, :, j], right[p, :, j], snap[p, :, j], times,
                                                  left[p, :, j], snap_left[p, :, j])
                               for p in range(1, len(a))]).T.reshape(len(times), -1)
    rows = np.column_stack([times, values, derivative])
    return float(values[0]), rows[0, 2:].copy(), rows


def _peaks_on_flow(s, j: int) -> np.ndarray | None:
    """An event run's largest local peaks of DOF j's |absolute acceleration| located on its exact flow, as
    time_measure's rows: around each of the samples' largest local maxima, each output step split at its events is
    searched for a zero of d|a|/dt falling (Brent's method on a' from the flow: an interior peak, its derivative the
    sensitivity's at that fixed time) and for a larger one-sided limit at an event, where the acceleration jumps
    (its derivative then moves with the event's time: S_a + a' dt*/dp). None where the support's motion has no
    rate."""
    from scipy.optimize import brentq

    from smdcli.solvers.peaks import local_peaks

    ground = s.ground_acceleration()
    if ground is not None and s.ground_acceleration(s.time[:1], rate=True) is None:
        return None
    events = np.array(sorted(s.event_moves), dtype=float)
    P = len(s.parameter)

    def at(t: float, left: bool = False):  # (a, a', da/dp, da'/dp) of DOF j, absolute
        a, rate, da, drate = (q[..., j] for q in s.exact_rates_at(t, left))
        if ground is not None:
            base, dbase = s.ground_acceleration([t])
            slope, dslope = s.ground_acceleration([t], rate=True)
            a, rate, da, drate = a + base[0], rate + slope[0], da + dbase[:, 0], drate + dslope[:, 0]
        return float(a), float(rate), da, drate

    sampled = s.acceleration[:, j] + (ground[0] if ground is not None else 0.0)
    _, near = local_peaks(s.time, sampled, None, None, count=2 * TIME_PEAKS)
    found = {}
    for k in np.unique(np.searchsorted(s.time, near)):
        lo, hi = s.time[max(k - 1, 0)], s.time[min(k + 1, len(s.time) - 1)]
        cuts = np.concatenate([[lo], events[(events > lo) & (events < hi)], [hi]])
        for start, end in zip(cuts[:-1], cuts[1:]):
            first, last = at(float(start)), at(float(end), left=True)
            best = [(abs(first[0]), start, first, start in s.event_moves), (abs(last[0]), end, last, end in s.event_moves)]
            sign = np.sign(first[0] if abs(first[0]) >= abs(last[0]) else last[0])
            if sign * first[1] > 0 > sign * last[1]:  # |a| rises, then falls: an interior peak
                t = brentq(lambda time: at(time)[1], float(start), float(end), xtol=1e-14 * max(abs(end), 1.0),
                           rtol=4 * EPS)
                inside = at(t)
                best.append((abs(inside[0]), t, inside, False))
            value, t, (a, rate, da, drate), moving = max(best, key=lambda item: item[0])
            derivative = np.sign(a) * (da + rate * s.event_moves[t] if moving else da)
            key = round(float(t), 12)
            if key not in found or found[key][1] < value:
                found[key] = np.concatenate([[t, value], derivative.reshape(P)])
    rows = np.array(sorted(found.values(), key=lambda row: -row[1])[:TIME_PEAKS])
    return rows if len(rows) else None


def _peaks_on_dense(s, j: int) -> np.ndarray:
    """A smooth nonlinear run's largest local peaks of DOF j's |absolute acceleration| located on its integrator's
    dense output, as time_measure's rows: around each of the samples' largest local maxima, each output step split
    where the integration restarted is searched by bounded Brent for the largest |a|, the acceleration from the
    equation at the dense state; its derivative the sensitivity's at that fixed time (a' = 0 there)."""
    from scipy.optimize import brentq, minimize_scalar

    from smdcli.solvers.peaks import local_peaks

    ground = s.ground_acceleration()
    dense = s.dense_acceleration_at

    def at(t: float, left: bool = False):  # (|a|, a, da/dp) of DOF j, absolute
        a, da = (q[..., j] for q in dense(t, left))
        if ground is not None:
            base, dbase = s.ground_acceleration([t])
            a, da = a + base[0], da + dbase[:, 0]
        return abs(float(a)), float(a), da

    step = float(s.time[1] - s.time[0])

    def slope(t: float) -> float:  # a' by a central difference over 1e-6 of a step: rounding and truncation 1e-8
        return at(t + 1e-6 * step)[1] - at(t - 1e-6 * step)[1]

    sampled = s.acceleration[:, j] + (ground[0] if ground is not None else 0.0)
    _, near = local_peaks(s.time, sampled, None, None, count=2 * TIME_PEAKS)
    found = {}
    for k in np.unique(np.searchsorted(s.time, near)):
        lo, hi = s.time[max(k - 1, 0)], s.time[min(k + 1, len(s.time) - 1)]
        cuts = np.concatenate([[lo], dense.breaks[(dense.breaks > lo) & (dense.breaks < hi)], [hi]])
        for start, end in zip(cuts[:-1], cuts[1:]):
            inside = minimize_scalar(lambda t: -at(t)[0], bounds=(float(start), float(end)), method="bounded",
                                     options={"xatol": 1e-13 * max(abs(end), 1.0)}).x
            # a flat top locates its time only to sqrt(eps), where a' times the peak time's own derivative would
            # join the gradient: the time refined as the zero of a' (a central difference on the dense output)
            reach = 1e-3 * (end - start)
            lo_t, hi_t = max(float(start), inside - reach), min(float(end), inside + reach)
            if lo_t < inside < hi_t and slope(lo_t) * slope(hi_t) < 0:
                inside = brentq(slope, lo_t, hi_t, xtol=4 * EPS * abs(inside), rtol=4 * EPS)
            best = max([(at(float(start)), start), (at(float(end), left=True), end), (at(inside), inside)],
                       key=lambda item: item[0][0])
            (value, a, da), t = best
            key = round(float(t), 12)
            if key not in found or found[key][1] < value:
                found[key] = np.concatenate([[t, value], np.sign(a) * da])
    return np.array(sorted(found.values(), key=lambda row: -row[1])[:TIME_PEAKS])


def acceleration_rates(s):
    """(a, a' right, a'' right, a' left, a'' left, kinks) of a linear scene's run s: the absolute acceleration and
    its first two time derivatives, right and left limits at each sample, each (P + 1, N, n) for the scene and the
    derivative in each parameter, from the model's equation differentiated in time on the scene and its
    sensitivity systems together (a' = M^-1 (B u' - C a - K v), a'' = M^-1 (B u'' - C a' - K a), relative, plus
    the ground's a_g' and a_g''); and the times inside a step where a force's slope jumps (its quintic does not
    span them). None for a scene solved otherwise or a force with no derivative."""
    from smdcli.analysis.model_derivative import augmented_model

    model = s.model
    if model is None or s.exact_at is not None or not model.is_linear or not len(s.time) > 2:
        return None
    stacked, scales = augmented_model(model, s.derivatives)
    try:
        first = [signal.derivative(float(s.time[0])) for signal in stacked.signals]
        second = [None if f is None else f.derivative(float(s.time[0])) for f in first]
    except NotImplementedError:
        return None
    N, n = s.displacement.shape
    weights = np.concatenate([[1.0], scales])

    def stack(nominal, derived):  # (N, n) and (P, N, n) -> (N, (P + 1) n), block i + 1 scaled
        return np.concatenate([nominal[None], derived]).transpose(1, 0, 2).reshape(N, -1) * \
            np.repeat(weights, n)[None]

    def values(signals, left):  # (N, inputs)
        return np.array([np.zeros(N) if f is None else np.broadcast_to(f.value_left(s.time) if left else
                                                                        f.value(s.time), (N,))
                         for f in signals]).T.reshape(N, len(signals))
    x, v, a = (stack(q, dq) for q, dq in ((s.displacement, s.d_displacement), (s.velocity, s.d_velocity),
                                          (s.acceleration, s.d_acceleration)))
    Minv = np.linalg.inv(stacked.M)
    B, C, K, G = stacked.B, stacked.C, stacked.K, stacked.ground_inputs
    out = [a + values(stacked.signals, False) @ G.T]
    for left in (False, True):
        u1, u2 = values(first, left), values(second, left)
        rate = (u1 @ B.T - a @ C.T - v @ K.T) @ Minv.T
        curvature = (u2 @ B.T - rate @ C.T - a @ K.T) @ Minv.T
        out += [rate + u1 @ G.T, curvature + u2 @ G.T]
    unstacked = [q.reshape(N, len(weights), n).transpose(1, 0, 2) / weights[:, None, None] for q in out]
    kinks = [t for f in first if f is not None for t in f.breakpoints(float(s.time[0]), float(s.time[-1]))
             if f.value(t) != f.value_left(t)]
    k = np.clip(np.searchsorted(s.time, kinks), 0, N - 1)
    inside = [t for t, i in zip(kinks, k) if abs(s.time[i] - t) > 1e-9 * (s.time[1] - s.time[0])]
    return (*unstacked, np.array(inside, dtype=float))
