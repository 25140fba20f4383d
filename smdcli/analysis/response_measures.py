"""The measures `smd optimize` minimizes, each with its exact gradient in the parameters: of a linear scene a
receptance's or a transmissibility's located peaks (the H-infinity norm) and the RMS under white noise (the H2
norm, by Lyapunov); of any scene's run its peaks, drifts, accelerations and residual displacement (from its
sensitivities).

derived: per parameter (dM, dC, dK), the model's derivatives (model_derivative's). Must not import: io, plots,
commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.errors import ScenarioError

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
    from scipy.optimize import brentq

    from smdcli.sweep.frequency import amplitude_slope  # the slope one frequency at a time, as the sweep locates

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

    def slopes_at(ws):  # d|R_dof|^2 / dw at each of ws at once (amplitude_slope's, vectorized over the grid)
        W = np.asarray(ws, dtype=float)[:, None, None]
        Z = K[None] - W**2 * M[None] + 1j * W * C[None]
        r, dr = load(ws)
        Y = np.linalg.solve(Z, r[..., None])
        dY = np.linalg.solve(Z, dr[..., None] - (-2 * W * M[None] + 1j * C[None]) @ Y)
        return 2.0 * (np.conj(offset + Y[:, dof, 0]) * dY[:, dof, 0]).real

    slopes = slopes_at(grid)  # every grid frequency at once
    located = [0.0] if slopes[1] < 0 else []
    for i in np.flatnonzero((slopes[:-1] > 0) & (slopes[1:] <= 0)):
        located.append(float(brentq(lambda w: amplitude_slope((M, C, K), w, dof, input_dof or 0, support)[0],
                                    grid[i], grid[i + 1], xtol=1e-15 * top, rtol=4 * EPS, maxiter=200)))
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


def rms(M, C, K, input_dof: int, dof: int, derived, other: int | None = None) -> tuple[float, np.ndarray]:
    """The RMS of x_dof (or of the drift x_dof - x_other) under white noise of one-sided PSD 1 N^2/Hz on the input,
    and its gradient (Lyapunov)."""
    from scipy.linalg import solve_continuous_lyapunov

    n = len(M)
    Minv = np.linalg.inv(M)

    def state(Mi, Cm, Km):
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n], A[n:, n:] = -Mi @ Km, -Mi @ Cm
        B = np.zeros(2 * n)
        B[n:] = Mi[:, input_dof]
        return A, B

    A, B = state(Minv, C, K)
    Sigma = solve_continuous_lyapunov(A, -0.5 * np.outer(B, B))
    pick = np.zeros(2 * n)  # the measured combination of the state
    pick[dof] = 1.0
    if other is not None and other >= 0:
        pick[other] -= 1.0
    variance = float(pick @ Sigma @ pick)
    if not variance > 0 or not np.isfinite(variance):
        raise ScenarioError("", "damping", "the RMS response to white noise is unbounded: the scene needs damping in "
                            "every mode its input reaches")
    value = math.sqrt(variance)
    gradient = []
    for dM, dC, dK in derived:
        dMinv = -Minv @ dM @ Minv
        dA = np.zeros_like(A)
        dA[n:, :n] = -(dMinv @ K + Minv @ dK)
        dA[n:, n:] = -(dMinv @ C + Minv @ dC)
        dB = np.zeros(2 * n)
        dB[n:] = dMinv[:, input_dof]
        rhs = dA @ Sigma + Sigma @ dA.T + 0.5 * (np.outer(dB, B) + np.outer(B, dB))
        dSigma = solve_continuous_lyapunov(A, -rhs)
        gradient.append(float(pick @ dSigma @ pick) / (2 * value))
    return value, np.array(gradient)


TIME_PEAKS = 8  # a largest peak in time minimized as the minimax over this many of its run's largest local peaks


def time_measure(s, measure) -> tuple[float, np.ndarray, np.ndarray | None]:
    """A time-domain measure of a run, its gradient from the run's sensitivities s, and the smooth pieces of a largest
    peak: the located peak of |x| or of a drift |x_a - x_b| with rows (time, |peak|, d|peak|/dp...) of the run's
    TIME_PEAKS largest local peaks in time (each one's derivative at its own time, the envelope theorem: the
    largest is their maximum, minimized as such); the largest sampled |a| (absolute under support motion: relative
    plus the ground's); |x| at the run's end."""
    from smdcli.solvers.peaks import local_peaks, quintic_at

    j, kind = measure.dof, measure.kind
    if kind == "residual_displacement":
        x = float(s.displacement[-1, j])
        return abs(x), np.sign(x) * s.d_displacement[:, -1, j], None
    if kind == "peak_acceleration":
        a, da = s.acceleration[:, j].copy(), s.d_acceleration[:, :, j].copy()
        ground = s.ground_acceleration()
        if ground is not None:
            a, da = a + ground[0], da + ground[1]
        k = int(np.argmax(np.abs(a)))
        return float(abs(a[k])), np.sign(a[k]) * da[:, k], None
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
