"""Writes records/suite/: twelve made-up ground acceleration records (filtered noise under an envelope, never a
download) in the three formats engineers receive them in, for `smd ida` and the record readers' tests:
four PEER NGA `.AT2` files (in g; the two layouts of the NPTS/DT line), four COSMOS v1.20 volume 2 `.V2` files
(cm/s^2; each with a second channel and a velocity series, as processed files carry) and four two-column `.csv`
files (time s, acceleration g).

Each record: band-limited Gaussian noise (4th-order Butterworth, zero phase) between 0.2 Hz and a top frequency
that varies from record to record, under a Saragoni-Hart-like envelope of varying strong-motion duration, its
baseline removed so the velocity and displacement
integrated from it end at zero, scaled to its own peak (0.15-0.45 g), sampled at 100 or
200 Hz. Run it again to recreate the files bit for bit: python records/make_record_suite.py
"""

from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfiltfilt

SUITE = Path(__file__).with_name("suite")
G = 9.80665


def synthetic(seed: int, draw: int = 0) -> tuple[float, np.ndarray]:
    """(dt, acceleration in g) of record `seed` (draw 1: its second horizontal component, the same sampling)."""
    rng = np.random.default_rng(1000 + seed + 5000 * draw)
    rate = 200.0 if seed % 3 == 0 else 100.0
    strong = 4.0 + 1.5 * (seed % 4)
    duration = strong + 12.0
    t = np.arange(int(duration * rate)) / rate
    top = 6.0 + 2.0 * (seed % 5)
    band = sosfiltfilt(butter(4, [0.2, top], btype="bandpass", fs=rate, output="sos"), rng.standard_normal(len(t)))
    envelope = np.where(t < 1.5, (t / 1.5) ** 2, np.where(t < 1.5 + strong, 1.0, np.exp(-0.5 * (t - 1.5 - strong))))
    a = band * envelope
    # less c1 e + c2 t e, chosen so that the velocity and the displacement integrated from rest both end at zero
    shapes = np.array([envelope, t * envelope])
    ends = lambda q: [np.trapezoid(q, t), np.trapezoid((t[-1] - t) * q, t)]  # noqa: E731 (v(T), d(T))
    a -= np.linalg.solve(np.array([ends(q) for q in shapes]).T, ends(a)) @ shapes
    peak = 0.15 + 0.3 * rng.random()
    return 1.0 / rate, a * peak / np.abs(a).max()


def at2_text(name: str, dt: float, g: np.ndarray, bare: bool) -> str:
    """A PEER NGA AT2 file: 4 header lines, values in g, 5 a line in E15.7 (CRLF line ends, as PEER serves them)."""
    sampling = f"{len(g):d}    {dt:.4f}    NPTS, DT" if bare else f"NPTS= {len(g):6d}, DT=   {dt:.4f} SEC"
    lines = ["PEER NGA STRONG MOTION DATABASE RECORD", f"SMD SYNTHETIC {name}, made by records/make_record_suite.py",
             "ACCELERATION TIME SERIES IN UNITS OF G", sampling]
    lines += ["".join(f"{v:15.7E}" for v in g[i:i + 5]) for i in range(0, len(g), 5)]
    return "\r\n".join(lines) + "\r\n"


def _fixed(values, per_line: int, form: str) -> list[str]:
    return ["".join(form.format(v) for v in values[i:i + per_line]) for i in range(0, len(values), per_line)]


def cosmos_series(name: str, channel: int, dt: float, values: np.ndarray, quantity: str) -> list[str]:
    """One COSMOS v1.20 volume 2 series: 13 text lines, 100 integer and 100 real header values, a comment, the
    data in (8F10.5) and its end line. Acceleration in cm/s^2 (code 4), velocity in cm/s (code 5)."""
    code, kind, units = (4, 1, "cm/sec2") if quantity == "acceleration" else (5, 2, "cm/sec")
    text = [f"Corrected {quantity:<12}  (Format v01.20 with 13 text lines) Src: smd synthetic",
            f"SMD synthetic record {name}, made by records/make_record_suite.py"] + \
        [f"Text header line {i}" for i in range(3, 14)]
    integers = np.full(100, -999, dtype=int)
    integers[0], integers[1], integers[2], integers[49] = 2, kind, code, channel
    reals = np.full(100, -999.0)
    reals[61], reals[62] = dt * 1000.0, dt * len(values)
    lines = text + ["  100 Integer-header values follow on  10 lines, Format= (10I8)"]
    lines += _fixed(integers, 10, "{:8d}")
    lines += ["  100 Real-header values follow on  20 lines, Format= (5F15.6)"]
    lines += _fixed(reals, 5, "{:15.6f}")
    lines += ['    1 Comment line(s) follow, each starting with a "|":', "| synthetic: filtered noise, no download"]
    lines += [f"{len(values):8d} {quantity} pts, approx {dt * len(values):5.0f} secs, units={units} ({code:02d}), "
              "Format=(8F10.5)"]
    lines += _fixed(values, 8, "{:10.5f}")
    lines += [f"End-of-data for Chan {channel:2d} {quantity}"]
    return lines


def main() -> None:
    """Write the twelve records."""
    from scipy.integrate import cumulative_trapezoid

    SUITE.mkdir(exist_ok=True)
    for seed in range(1, 13):
        dt, g = synthetic(seed)
        name = f"record_{seed:02d}"
        if seed <= 4:
            (SUITE / f"{name}.AT2").write_bytes(at2_text(name, dt, g, bare=seed % 2 == 0).encode())
        elif seed <= 8:
            cm = np.round(g * G * 100.0, 5)
            other = np.round(synthetic(seed, draw=1)[1] * G * 100.0, 5)
            lines = cosmos_series(name, 1, dt, cm, "acceleration")
            lines += cosmos_series(name, 1, dt, np.round(cumulative_trapezoid(cm, dx=dt, initial=0.0), 5), "velocity")
            lines += cosmos_series(name, 2, dt, other, "acceleration")
            (SUITE / f"{name}.V2").write_text("\n".join(lines) + "\n")
        else:
            t = dt * np.arange(len(g))
            rows = ["time_s,acceleration_g"] + [f"{ti:.4f},{ai:.7f}" for ti, ai in zip(t, g)]
            (SUITE / f"{name}.csv").write_text("\n".join(rows) + "\n")
    print(f"wrote 12 records to {SUITE}")


if __name__ == "__main__":
    main()
