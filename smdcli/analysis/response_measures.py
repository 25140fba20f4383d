"""The measures `smd optimize` minimizes of a linear scene, each with its exact gradient in the parameters: a
receptance's located peaks (the H-infinity norm) and the RMS under white noise (the H2 norm, by Lyapunov).

derived: per parameter (dM, dC, dK), the model's derivatives (model_derivative's). Must not import: io, plots,
commands, cli.
"""

from __future__ import annotations

import math

import numpy as np

from smdcli.errors import ScenarioError

GRID_POINTS = 400  # frequencies a receptance is first sampled at: its peaks then located to rounding between them
EPS = float(np.finfo(float).eps)


def dynamic_stiffness(M, C, K, w: float) -> np.ndarray:
    """Z(w) = K - w^2 M + i w C."""
    return K - w * w * M + 1j * w * C


def receptance_peaks(M, C, K, input_dof: int, dof: int, derived) -> np.ndarray:
    """Every local maximum of |H_dof(w)| over w >= 0 (w = 0 where |H| falls from it), rows (w, |H|, d|H|/dp...),
    located as the zeros of d|H|^2/dw between the neighbours of a grid over the modes; the derivative at each
    peak's fixed frequency (the envelope theorem)."""
    from scipy.optimize import brentq

    n = len(M)
    b = np.zeros(n, complex)
    b[input_dof] = 1.0
    squared = np.linalg.eigvals(np.linalg.solve(M, K)).real
    top = math.sqrt(max(float(squared.max(initial=0.0)), 0.0)) or 1.0
    grid = np.concatenate([[0.0], np.geomspace(1e-3 * top, 3.0 * top, GRID_POINTS)])

    def slope(w: float) -> float:  # d|H_dof|^2 / dw
        Z = dynamic_stiffness(M, C, K, w)
        H = np.linalg.solve(Z, b)
        dH = -np.linalg.solve(Z, (-2 * w * M + 1j * C) @ H)
        return 2.0 * float((np.conj(H[dof]) * dH[dof]).real)

    W = grid[:, None, None]
    Z = K[None] - W**2 * M[None] + 1j * W * C[None]  # every grid frequency at once
    H = np.linalg.solve(Z, np.broadcast_to(b, (len(grid), n))[..., None])
    dH = -np.linalg.solve(Z, (-2 * W * M[None] + 1j * C[None]) @ H)
    slopes = 2.0 * (np.conj(H[:, dof, 0]) * dH[:, dof, 0]).real
    located = [0.0] if slopes[1] < 0 else []
    for i in np.flatnonzero((slopes[:-1] > 0) & (slopes[1:] <= 0)):
        located.append(float(brentq(slope, grid[i], grid[i + 1], xtol=1e-15 * top, rtol=4 * EPS, maxiter=200)))
    if slopes[-1] > 0:  # still rising at 3 times the highest mode: a massless DOF or a rigid input; take the end
        located.append(float(grid[-1]))
    rows = []
    for w in located:
        Z = dynamic_stiffness(M, C, K, w)
        H = np.linalg.solve(Z, b)
        size = abs(H[dof])
        row = [w, size]
        for dM, dC, dK in derived:
            dH = -np.linalg.solve(Z, dynamic_stiffness(dM, dC, dK, w) @ H)
            row.append(float((np.conj(H[dof]) * dH[dof]).real) / size if size else 0.0)
        rows.append(row)
    return np.array(rows, dtype=float).reshape(len(rows), 2 + len(derived))


def rms(M, C, K, input_dof: int, dof: int, derived) -> tuple[float, np.ndarray]:
    """The RMS of x_dof under white noise of one-sided PSD 1 N^2/Hz on the input, and its gradient (Lyapunov)."""
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
    variance = float(Sigma[dof, dof])
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
        gradient.append(float(dSigma[dof, dof]) / (2 * value))
    return value, np.array(gradient)
