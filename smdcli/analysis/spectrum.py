"""Response spectra of a ground acceleration record, exact: the peak of each oscillator's continuous response.

A record is taken as linear between samples. A 1-DOF oscillator y'' + 2 zeta w y' + w^2 y = -a(t) under such an
input is solved in closed form over each sample interval, and the peak of |y| is located between samples as the
root of the closed-form velocity (smdcli.kernels.oscillator): no sub-sampling, no parabola. Peers step the same
equation by Newmark's average acceleration or by the Nigam-Jennings recurrence and take the largest sample.

Each oscillator needs only its own state, so memory does not grow with the record; oscillators are taken in groups
(for the progress callback) and shared among threads within a group.

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from smdcli.kernels.oscillator import PIECES_PER_PERIOD

STATE_VALUES = 2**22  # oscillators x record samples per group: a progress report every few million piece steps


@dataclass(frozen=True)
class Spectrum:
    """Sd (m), Sv = w Sd (m/s) and Sa = w^2 Sd (m/s^2) per damping ratio and period: (Z, P) each."""

    period: np.ndarray
    damping: np.ndarray
    Sd: np.ndarray

    @property
    def omega(self) -> np.ndarray:
        """Circular frequency per period, rad/s."""
        return 2 * math.pi / self.period

    @property
    def Sv(self) -> np.ndarray:
        """Pseudo-spectral velocity, m/s."""
        return self.Sd * self.omega

    @property
    def Sa(self) -> np.ndarray:
        """Pseudo-spectral acceleration, m/s^2."""
        return self.Sd * self.omega**2


MAX_PIECES_PER_INTERVAL = 4096  # a period below 8 dt / 4096 has no meaning on such a record
MAX_WORK = 2e9  # pieces of closed-form response over the whole run (about 10-20 s on 2 cores)


def spectrum_cost(samples: int, dt: float, periods: np.ndarray, dampings: int) -> tuple[float, float]:
    """(the most pieces any oscillator needs per record interval, all pieces of the run): what response_spectrum
    would compute, estimated in floating point before anything runs."""
    with np.errstate(all="ignore"):
        per_interval = np.maximum(1.0, np.ceil(PIECES_PER_PERIOD * dt / np.asarray(periods, dtype=float)))
    most = float(per_interval.max(initial=1.0))
    return most, float(per_interval.sum() * max(samples - 1, 1) * dampings)


def response_spectrum(time: np.ndarray, acceleration: np.ndarray, periods: np.ndarray,
                      dampings: np.ndarray, advance=None) -> Spectrum:
    """Peak relative displacement of every (damping, period) oscillator over the record, from rest; advance(k),
    if given, is told of every k oscillators done."""
    from smdcli.kernels.oscillator import DISPLACEMENT, extremes

    periods = np.asarray(periods, dtype=float)
    dampings = np.asarray(dampings, dtype=float)
    Z, P = len(dampings), len(periods)
    omega = np.tile(2 * math.pi / periods, Z)
    zeta = np.repeat(dampings, P)
    dt = float(time[1] - time[0])
    a = np.asarray(acceleration, dtype=float)
    O = len(omega)
    peak = np.empty(O)
    group = max(1, STATE_VALUES // len(a))
    for lo in range(0, O, group):
        part = slice(lo, min(O, lo + group))
        found = extremes(a, dt, omega[part], zeta[part], DISPLACEMENT)
        peak[part] = np.maximum(found[:, 0], -found[:, 2])
        if advance is not None:
            advance(part.stop - part.start)
    return Spectrum(periods, dampings, peak.reshape(Z, P))
