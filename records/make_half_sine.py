"""Writes half_sine_11ms_50g.csv: the classic shock test pulse (a 50 g, 11 ms half-sine, as MIL-STD-810 and
IEC 60068-2-27 specify it), sampled at 100 kHz, with 1 ms of rest after it. Run it again to recreate the file:
python records/make_half_sine.py
"""

from pathlib import Path

import numpy as np

PEAK_G, DURATION_S, RATE_HZ, REST_S = 50.0, 0.011, 100_000.0, 0.001


def half_sine() -> tuple[np.ndarray, np.ndarray]:
    """Time (s) and acceleration (g) of the pulse."""
    t = np.arange(int(round((DURATION_S + REST_S) * RATE_HZ)) + 1) / RATE_HZ
    return t, np.where(t < DURATION_S, PEAK_G * np.sin(np.pi * np.minimum(t, DURATION_S) / DURATION_S), 0.0)


if __name__ == "__main__":
    t, a = half_sine()
    out = Path(__file__).with_name("half_sine_11ms_50g.csv")
    out.write_text("\n".join(["time_s,acceleration_g"] + [f"{ti:.5f},{float(ai)!r}" for ti, ai in zip(t, a)]) + "\n")
    print(f"wrote {out}: {len(t)} samples")
