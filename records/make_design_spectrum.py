"""Writes design_spectrum_sds1_sd06.csv: a design response spectrum of the shape ASCE 7 prescribes (5 % damping),
with S_DS = 1.0 g, S_D1 = 0.6 g and T_L = 8 s, tabulated at 200 log-spaced periods from 0.01 to 10 s plus the
corner periods T0 and TS (where the shape changes). Run it again to recreate the file:
python records/make_design_spectrum.py
"""

from pathlib import Path

import numpy as np

SDS, SD1, TL = 1.0, 0.6, 8.0


def design_spectrum() -> tuple[np.ndarray, np.ndarray]:
    """Period (s) and Sa (g)."""
    T0, TS = 0.2 * SD1 / SDS, SD1 / SDS
    T = np.unique(np.concatenate([np.logspace(-2, 1, 200), [T0, TS, TL]]))
    Sa = np.where(T < T0, SDS * (0.4 + 0.6 * T / T0),
                  np.where(T <= TS, SDS, np.where(T <= TL, SD1 / T, SD1 * TL / T**2)))
    return T, Sa


if __name__ == "__main__":
    T, Sa = design_spectrum()
    out = Path(__file__).with_name("design_spectrum_sds1_sd06.csv")
    out.write_text("\n".join(["period_s,Sa_g"] + [f"{t!r},{s!r}" for t, s in zip(T.tolist(), Sa.tolist())]) + "\n")
    print(f"wrote {out}: {len(T)} periods")
