"""The shock response spectrum (SRS) of a support acceleration: the extremes of the absolute acceleration of
1-DOF oscillators over natural frequency, for quality factors Q = 1 / (2 zeta).

Each oscillator's response is exact for the record taken as linear between samples, and every extreme is located
between samples as the root of the closed-form derivative (smdcli.kernels.oscillator), over the record and the
residual free motion after it (1.25 of the oscillator's periods, which hold its largest residual swing in either
direction since free motion only decays). The record's own sampling is the only approximation: a smooth pulse
sampled every dt differs from its straight-line interpolation by about (pi dt / duration)^2 / 12 of the response.

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

RESIDUAL_PERIODS = 1.25


@dataclass(frozen=True)
class ShockSpectrum:
    """positive, negative (the most negative, a negative number) and maximax absolute acceleration, in the record's
    units, per quality factor and natural frequency: (Q, F) each, with the times the extremes occur."""

    frequency: np.ndarray  # Hz
    q: np.ndarray
    positive: np.ndarray
    negative: np.ndarray
    positive_time: np.ndarray
    negative_time: np.ndarray

    @property
    def maximax(self) -> np.ndarray:
        """The largest absolute value of either sign."""
        return np.maximum(self.positive, -self.negative)

    @property
    def damping(self) -> np.ndarray:
        """The damping ratio of each quality factor, 1 / (2 Q)."""
        return 1.0 / (2.0 * self.q)


def shock_response_spectrum(time: np.ndarray, acceleration: np.ndarray, frequency_hz: np.ndarray,
                            q: np.ndarray) -> ShockSpectrum:
    """The SRS of a record sampled at a uniform step over natural frequencies (Hz) and quality factors, from rest."""
    from smdcli.kernels.oscillator import ABSOLUTE_ACCELERATION, extremes

    frequency_hz = np.asarray(frequency_hz, dtype=float)
    q = np.asarray(q, dtype=float)
    Q, F = len(q), len(frequency_hz)
    omega = np.tile(2 * math.pi * frequency_hz, Q)
    zeta = np.repeat(1.0 / (2.0 * q), F)
    dt = float(time[1] - time[0])
    found = extremes(np.asarray(acceleration, dtype=float), dt, omega, zeta, ABSOLUTE_ACCELERATION,
                     RESIDUAL_PERIODS).reshape(Q, F, 4)
    start = float(time[0])
    return ShockSpectrum(frequency_hz, q, found[..., 0], found[..., 2], found[..., 1] + start, found[..., 3] + start)
