"""The exact flow of a linear mode with constant forcing, z' = A z + b: z(t) = E(t) z + Phi(t) b from one matrix
exponential of [[A, I], [0, 0]] t, cached by step, and Gauss-Legendre nodes on it for the energy integrals.

Must not import: sweep, io, plots, commands, cli.
"""

from __future__ import annotations

import numpy as np

GAUSS_POINTS = 8
SPECTRAL_CONDITION = 1e4  # eigenvector condition up to which arbitrary steps are taken from the eigenvectors
_LEGENDRE = np.polynomial.legendre.leggauss(GAUSS_POINTS)
NODES, WEIGHTS = (_LEGENDRE[0] + 1) / 2, _LEGENDRE[1] / 2  # Gauss-Legendre on [0, 1]


class Flow:
    """exp([[A, I], [0, 0]] t) of a mode's A: z(t) = E z + Phi b, cached by step; shared by the modes with one A."""

    def __init__(self, A: np.ndarray):
        s = len(A)
        self.s = s
        self.big = np.zeros((2 * s, 2 * s))
        self.big[:s, :s] = A
        self.big[:s, s:] = np.eye(s)
        self.cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self.nodes: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        values, vectors = np.linalg.eig(A) if s else (np.zeros(0), np.zeros((0, 0)))
        self.omega = float(np.abs(values).max(initial=0.0))
        # The eigenvectors serve the arbitrary steps of event location (a few microseconds each, not an
        # exponential's hundred): where they are well conditioned, to within SPECTRAL_CONDITION eps
        self.spectral = None
        if s and np.linalg.cond(vectors) < SPECTRAL_CONDITION:
            self.spectral = (values, vectors, np.linalg.inv(vectors))

    def operators(self, h: float, keep: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(E(h), Phi(h)): cached steps by the exponential, the rest from the eigenvectors where they serve."""
        if h in self.cache:
            return self.cache[h]
        if not keep and self.spectral is not None:
            values, vectors, inverse = self.spectral
            growth = np.exp(values * h)
            small = np.abs(values * h) < 1e-8  # (e^(l h) - 1) / l, to rounding where l h is tiny
            integral = np.where(small, h * (1 + 0.5 * values * h), (growth - 1) / np.where(small, 1.0, values))
            return ((vectors * growth) @ inverse).real, ((vectors * integral) @ inverse).real
        from scipy.linalg import expm

        s = self.s
        full = expm(self.big * h)
        pair = (full[:s, :s], full[:s, s:])
        if keep:
            self.cache[h] = pair
        return pair

    def at(self, z: np.ndarray, b: np.ndarray, h: float, keep: bool = False) -> np.ndarray:
        """z after h."""
        if h == 0:
            return z.copy()
        E, Phi = self.operators(h, keep)
        return E @ z + Phi @ b

    def gauss_operators(self, h: float, keep: bool) -> tuple[np.ndarray, np.ndarray]:
        """(E, Phi) at the Gauss-Legendre nodes of [0, h], (GAUSS_POINTS, s, s) each."""
        if keep and h in self.nodes:
            return self.nodes[h]
        pairs = [self.operators(h * c) for c in NODES]
        found = np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])
        if keep:
            self.nodes[h] = found
        return found
