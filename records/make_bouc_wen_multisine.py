"""Writes bouc_wen_benchmark_multisine.csv: a random-phase multisine force like the excitation of the Bouc-Wen
benchmark of Noel and Schoukens (nonlinearbenchmark.org): lines from 5 to 150 Hz at the resolution of 8192 samples
at 750 Hz, equal amplitudes, RMS 50 N, one period (10.92 s). Made here from a fixed seed, never a download.
Run it again to recreate the file: python records/make_bouc_wen_multisine.py
"""

from pathlib import Path

import numpy as np

RATE_HZ, SAMPLES, BAND_HZ, RMS_N, SEED = 750.0, 8192, (5.0, 150.0), 50.0, 20160914


def multisine() -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and force (N): one period, and its first sample again at the end (the period closes)."""
    lines = np.arange(SAMPLES // 2 + 1) * RATE_HZ / SAMPLES
    chosen = np.flatnonzero((lines >= BAND_HZ[0]) & (lines <= BAND_HZ[1]))
    phases = np.random.default_rng(SEED).uniform(0.0, 2 * np.pi, len(chosen))
    t = np.arange(SAMPLES + 1) / RATE_HZ
    u = np.cos(2 * np.pi * np.outer(t, lines[chosen]) + phases).sum(axis=1)
    return t, u * RMS_N / np.sqrt(np.mean(u[:-1] ** 2))


if __name__ == "__main__":
    t, u = multisine()
    out = Path(__file__).with_name("bouc_wen_benchmark_multisine.csv")
    out.write_text("\n".join(["time_s,force_N"] + [f"{float(ti)!r},{float(ui)!r}" for ti, ui in zip(t, u)]) + "\n")
    print(f"wrote {out}: {len(t)} samples, RMS {np.sqrt(np.mean(u[:-1] ** 2)):.6g} N")
