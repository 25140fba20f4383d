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
