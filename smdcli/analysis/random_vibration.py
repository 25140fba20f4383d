"""Random vibration of a linear scene: the stationary response to a support acceleration PSD or a force PSD on a
mass, from the scene's frequency response, and, for white noise, exactly from the Lyapunov equation.

PSDs are one-sided, per Hz, as test standards tabulate them (g^2/Hz for acceleration, N^2/Hz for force): the
variance of a quantity q is the integral over f >= 0 of |H_q(f)|^2 S(f). A profile is a table of (f, S) points
interpolated log-log (a straight line in dB/octave between breakpoints) and zero outside them.

Coordinates: x relative to the support, so M x'' + C x' + K x = -M r a_g (support input, r ones) or = e_j F (a
force on DOF j); the absolute acceleration of a DOF is x'' + a_g = -M^-1 (C x' + K x) for support input. Every
response quantity q is linear in the state z = (x, x'): q = L z, and in frequency H_q = L (i w I - A)^-1 B.

- profile: the variance is integrated over each profile segment with scipy's quad_vec (relative 1e-12), the
  natural frequencies inside a segment given as break points, all quantities at once;
- white noise of level S0 over all frequencies: the covariance P of z solves A P + P A^T + B (S0 / 2) B^T = 0
  (a one-sided S0 per Hz is a two-sided intensity S0 / 2), and var q = L P L^T: no quadrature at all.

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Quantities:
    """The response quantities as rows of L over the state (x, x'), with names and units."""

    L: np.ndarray  # (q, 2n)
    names: tuple[str, ...]
    groups: tuple[str, ...]  # displacement | velocity | acceleration | spring_force | damper_force, per row


def quantities(M: np.ndarray, C: np.ndarray, K: np.ndarray, dofs, springs=(), dampers=()) -> Quantities:
    """Displacement, velocity and acceleration of each DOF (absolute acceleration for a support input), and the
    force in each spring and damper ((a, b, coefficient) with node indices, -1 the ground)."""
    n = len(M)
    Minv = np.linalg.inv(M)
    rows, names, groups = [], [], []
    for j, name in enumerate(dofs):
        e = np.zeros(2 * n)
        e[j] = 1.0
        rows.append(e)
        names.append(name)
        groups.append("displacement")
    for j, name in enumerate(dofs):
        e = np.zeros(2 * n)
        e[n + j] = 1.0
        rows.append(e)
        names.append(name)
        groups.append("velocity")
    accel = np.hstack([-Minv @ K, -Minv @ C])  # x'' + a_g for a support input; x'' less M^-1 F for a force
    for j, name in enumerate(dofs):
        rows.append(accel[j])
        names.append(name)
        groups.append("acceleration")
    for kind, elements in (("spring_force", springs), ("damper_force", dampers)):
        for name, a, b, coefficient in elements:
            e = np.zeros(2 * n)
            offset = 0 if kind == "spring_force" else n
            if b >= 0:
                e[offset + b] += coefficient
            if a >= 0:
                e[offset + a] -= coefficient
            rows.append(e)
            names.append(name)
            groups.append(kind)
    return Quantities(np.array(rows), tuple(names), tuple(groups))


def input_vector(M: np.ndarray, support: bool, dof: int | None = None) -> np.ndarray:
    """B: the state's response to a unit input: support acceleration (-r) or a unit force on `dof`."""
    n = len(M)
    B = np.zeros(2 * n)
    B[n:] = -np.ones(n) if support else np.linalg.solve(M, np.eye(n)[dof])
    return B


def state_matrix(M, C, K) -> np.ndarray:
    """A of z' = A z + B u."""
    n = len(M)
    Minv = np.linalg.inv(M)
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])


def transfer(A: np.ndarray, B: np.ndarray, Q: Quantities, f: np.ndarray, support: bool) -> np.ndarray:
    """H_q(f) for every quantity, (len(f), q) complex; for a force input the acceleration rows gain M^-1 F."""
    n2 = len(A)
    H = np.empty((len(f), len(Q.names)), dtype=complex)
    eye = np.eye(n2)
    for i, fi in enumerate(np.atleast_1d(f)):
        z = np.linalg.solve(2j * math.pi * fi * eye - A, B)
        H[i] = Q.L @ z
    if not support:  # the applied force's own share of the acceleration: x'' = ... + M^-1 F (B's lower half)
        accel = np.array([g == "acceleration" for g in Q.groups])
        H[:, accel] += B[n2 // 2:][None, :]
    return H


def white_noise_variance(A: np.ndarray, B: np.ndarray, Q: Quantities, level: float, support: bool) -> np.ndarray:
    """var q of every quantity under one-sided white noise of `level` per Hz over all frequencies (Lyapunov)."""
    from scipy.linalg import solve_continuous_lyapunov

    P = solve_continuous_lyapunov(A, -np.outer(B, B) * (level / 2.0))
    variance = np.einsum("qi,ij,qj->q", Q.L, P, Q.L)
    if not support:  # a DOF the force reaches directly (M^-1 F) has a white acceleration: infinite variance
        n = len(B) // 2
        rows = [i for i, g in enumerate(Q.groups) if g == "acceleration"]
        for j, row in enumerate(rows):
            if B[n + j] != 0.0:
                variance[row] = np.inf
    return variance


@dataclass(frozen=True)
class Profile:
    """A one-sided PSD as breakpoints (Hz, level > 0 per Hz), log-log between them and zero outside."""

    frequency: np.ndarray
    level: np.ndarray

    def __call__(self, f: np.ndarray) -> np.ndarray:
        """The level at f (zero outside the breakpoints)."""
        f = np.asarray(f, dtype=float)
        out = np.zeros_like(f)
        inside = (f >= self.frequency[0]) & (f <= self.frequency[-1])
        out[inside] = np.exp(np.interp(np.log(f[inside]), np.log(self.frequency), np.log(self.level)))
        return out

    def segments(self):
        """(f0, f1, S0, S1) of each segment."""
        yield from zip(self.frequency[:-1], self.frequency[1:], self.level[:-1], self.level[1:])

    @property
    def rms(self) -> float:
        """The input's own RMS: the square root of its area (log-log segments integrated in closed form)."""
        total = 0.0
        for f0, f1, s0, s1 in self.segments():
            slope = math.log(s1 / s0) / math.log(f1 / f0)
            total += (s0 * f0 * ((f1 / f0) ** (slope + 1) - 1) / (slope + 1) if abs(slope + 1) > 1e-12
                      else s0 * f0 * math.log(f1 / f0))
        return math.sqrt(total)


def profile_variance(A: np.ndarray, B: np.ndarray, Q: Quantities, profile: Profile, support: bool,
                     natural_hz: np.ndarray) -> np.ndarray:
    """var q of every quantity under a profile: each segment integrated by quad_vec to a relative 1e-12, its
    natural frequencies as break points."""
    from scipy.integrate import quad_vec

    total = np.zeros(len(Q.names))
    for f0, f1, _, _ in profile.segments():
        inside = [float(f) for f in natural_hz if f0 < f < f1]

        def integrand(f):
            return np.abs(transfer(A, B, Q, np.array([f]), support)[0]) ** 2 * profile(np.array([f]))[0]

        value, _ = quad_vec(integrand, f0, f1, epsrel=1e-12, epsabs=0.0, points=inside or None, limit=10_000)
        total += value
    return total
