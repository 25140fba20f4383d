"""What a scene's modes are: natural frequencies, damping ratios, regimes and shapes, as the model states them.

Must not import: anything of smd but the model layer's bottom (a leaf the model's modules share).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RIGID_BODY = 1e-6  # a natural frequency below this fraction of the largest is a rigid-body mode's zero
# Relative width around zeta = 1 inside which a mode is called critically damped.
CRITICAL_BAND = 1e-8


@dataclass(frozen=True)
class Modes:
    """Modes of the linear part, from the eigenvalues of the state matrix."""

    eigenvalues: np.ndarray  # (2n,) complex
    natural_frequencies: np.ndarray  # (n,) rad/s
    damping_ratios: np.ndarray  # (n,)
    regimes: tuple[str, ...]
    shapes: np.ndarray  # (n, n) undamped mass-normalized mode shapes, columns


def regime(zeta: float, omega: float = 1.0) -> str:
    """The damping regime's name for a damping ratio; a mode of zero natural frequency is a rigid-body one (it has
    no restoring stiffness, and its damping ratio is not defined)."""
    if omega == 0.0:
        return "rigid-body"
    if zeta == 0.0:
        return "undamped"
    if abs(zeta - 1.0) <= CRITICAL_BAND:
        return "critically damped"
    return "underdamped" if zeta < 1.0 else "overdamped"


def modal_eigenvalues(c: np.ndarray, squared: np.ndarray) -> np.ndarray:
    """The state eigenvalues of modes of damping c (diagonal of Phi^T C Phi) and squared frequencies: the roots of
    s^2 + c s + w^2, all first roots then all second."""
    root = np.sqrt((c * c - 4 * squared).astype(complex))
    return np.concatenate([(-c + root) / 2, (-c - root) / 2])


def signed(shapes: np.ndarray) -> np.ndarray:
    """Mode shapes with the sign LAPACK leaves free fixed: the first entry within 1e-6 of the column's largest is
    positive (a tie broken by position, not by which rounding came out larger)."""
    size = np.abs(shapes)
    lead = np.argmax(size >= (1 - 1e-6) * size.max(axis=0), axis=0)
    return shapes * np.where(shapes[lead, np.arange(shapes.shape[1])] < 0, -1.0, 1.0)
