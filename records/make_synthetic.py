"""Writes synthetic_20s_100hz.csv: a made-up ground acceleration record (filtered noise), never a download.

Band-limited Gaussian noise (4th-order Butterworth band-pass, 0.3-12 Hz, applied forwards and backwards) under a
Saragoni-Hart-like envelope (rise to 2 s, strong motion to 8 s, exponential decay), scaled to a peak of 0.3 g;
its mean is removed so the integrated velocity ends at zero. 20 s at 100 Hz, seed 2026. Run it again to
recreate the file bit for bit: python records/make_synthetic.py
"""

from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

RATE_HZ, DURATION_S, PEAK_G, SEED = 100.0, 20.0, 0.3, 2026


def synthetic_record() -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and acceleration (g) of the synthetic record."""
    t = np.arange(int(DURATION_S * RATE_HZ) + 1) / RATE_HZ
    noise = np.random.default_rng(SEED).standard_normal(len(t))
    band = sosfiltfilt(butter(4, [0.3, 12.0], btype="bandpass", fs=RATE_HZ, output="sos"), noise)
    envelope = np.where(t < 2.0, (t / 2.0) ** 2, np.where(t < 8.0, 1.0, np.exp(-0.4 * (t - 8.0))))
    a = band * envelope
    a -= np.trapezoid(a, t) / (t[-1] - t[0]) * envelope / np.trapezoid(envelope, t) * (t[-1] - t[0])
    return t, np.round(a * PEAK_G / np.abs(a).max(), 6)


if __name__ == "__main__":
    t, a = synthetic_record()
    out = Path(__file__).with_name("synthetic_20s_100hz.csv")
    lines = ["time_s,acceleration_g"] + [f"{ti:.2f},{ai:.6f}" for ti, ai in zip(t, a)]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}: {len(t)} samples, peak {np.abs(a).max():.3f} g")
