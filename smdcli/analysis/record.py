"""Processing a ground acceleration record and the intensity measures engineers quote.

The record is a uniformly sampled acceleration a_k, taken as linear between samples (as everywhere in smd):

- baseline correction: the polynomial of the chosen degree (1 linear, 2 quadratic) fitted to a by least squares
  is subtracted, so a drift of that degree or lower is removed to rounding (the fit is linear in the record);
- band-pass: a zero-phase Butterworth filter (scipy's sosfiltfilt: forwards and backwards, so the order doubles
  and the phase is zero), low-pass where LOW = 0, high-pass where HIGH = 0;
- velocity and displacement are the exact integrals of the straight lines: v_{k+1} = v_k + dt (a_k + a_{k+1}) / 2,
  d_{k+1} = d_k + dt v_k + dt^2 (2 a_k + a_{k+1}) / 6, from rest;
- PGA, PGV, PGD: the largest |a|, |v|, |d| at the samples;
- Arias intensity I_A = pi / (2 g) * integral of a^2 (trapezoid rule, as OpenSeismoMatlab and eqsig take it); its
  running value normalised by the total is the Husid curve; the significant durations D5-95 and D5-75 are the
  times between the Husid curve's crossings of 5 % and 95 % (75 %), each crossing interpolated linearly between
  samples;
- CAV: the integral of |a| (trapezoid rule);
- Housner spectrum intensity SI: the integral of the 5 %-damped pseudo-velocity over periods 0.1 to 2.5 s
  (trapezoid over HOUSNER_PERIODS periods, each spectral value exact).

Must not import: commands, io, plots, cli.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from smdcli.scenario.records import BASELINES, band_passed, baseline_corrected
from smdcli.scenario.spec import STANDARD_GRAVITY

__all__ = ["BASELINES", "band_passed", "baseline_corrected", "integrated", "process"]

HOUSNER_PERIODS = np.linspace(0.1, 2.5, 241)


def integrated(acceleration: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """(velocity, displacement) at the samples: the exact integrals of the straight lines, from rest."""
    a = np.asarray(acceleration, dtype=float)
    v = np.concatenate([[0.0], np.cumsum(step * 0.5 * (a[:-1] + a[1:]))])
    d_step = step * v[:-1] + step * step * (2.0 * a[:-1] + a[1:]) / 6.0
    return v, np.concatenate([[0.0], np.cumsum(d_step)])


def _crossing(time: np.ndarray, curve: np.ndarray, level: float) -> float:
    """The first time a non-decreasing curve reaches `level`, linear between samples."""
    k = int(np.searchsorted(curve, level, side="left"))
    if k == 0:
        return float(time[0])
    c0, c1 = curve[k - 1], curve[k]
    return float(time[k - 1] + (time[k] - time[k - 1]) * (level - c0) / (c1 - c0))


@dataclass(frozen=True)
class Measures:
    """The intensity measures of a processed record (SI units: m/s^2, m/s, m, s)."""

    pga: float
    pgv: float
    pgd: float
    arias: float  # m/s
    d5_95: float
    d5_75: float
    cav: float  # m/s
    housner: float  # m
    t5: float
    t75: float
    t95: float


@dataclass(frozen=True)
class ProcessedRecord:
    """A record as read and as processed, its integrals, running Arias intensity and measures."""

    time: np.ndarray
    raw: np.ndarray
    acceleration: np.ndarray
    velocity: np.ndarray
    displacement: np.ndarray
    arias: np.ndarray  # running, m/s
    measures: Measures
    baseline: str
    band: tuple[float, float] | None
    order: int


def process(time: np.ndarray, acceleration: np.ndarray, baseline: str = "none",
            band: tuple[float, float] | None = None, order: int = 4) -> ProcessedRecord:
    """Baseline-correct, then filter, then integrate and measure a record (acceleration in m/s^2)."""
    from scipy.integrate import cumulative_trapezoid

    from smdcli.analysis.spectrum import response_spectrum

    time = np.asarray(time, dtype=float)
    raw = np.asarray(acceleration, dtype=float)
    step = float(time[1] - time[0])
    a = baseline_corrected(time, raw, BASELINES[baseline])
    if band is not None:
        a = band_passed(a, step, band[0], band[1], order)
    v, d = integrated(a, step)
    arias = math.pi / (2 * STANDARD_GRAVITY) * cumulative_trapezoid(a * a, time, initial=0.0)
    total = arias[-1]
    husid = arias / total if total > 0 else np.zeros_like(arias)
    t5, t75, t95 = (_crossing(time, husid, level) for level in (0.05, 0.75, 0.95))
    spectrum = response_spectrum(time, a, HOUSNER_PERIODS, np.array([0.05]))
    measures = Measures(pga=float(np.abs(a).max()), pgv=float(np.abs(v).max()), pgd=float(np.abs(d).max()),
                        arias=float(total), d5_95=t95 - t5, d5_75=t75 - t5,
                        cav=float(np.trapezoid(np.abs(a), time)),
                        housner=float(np.trapezoid(spectrum.Sv[0], HOUSNER_PERIODS)), t5=t5, t75=t75, t95=t95)
    return ProcessedRecord(time, raw, a, v, d, arias, measures, baseline, band, order)
