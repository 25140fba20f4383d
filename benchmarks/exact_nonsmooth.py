"""Benchmark (on demand, not in CI): the exact event-to-event solver against the compiled DOP853 at rtol 1e-8 on
the bundled scenes of yield, friction and stops, in one process, interleaved: median wall times, their ratio, the
events, and DOP853's largest difference from the exact run relative to the peak.

    python benchmarks/exact_nonsmooth.py [--repeats 5] [STEM ...]
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import numpy as np

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

ROOT = Path(__file__).resolve().parents[1]
SCENES = ["coulomb_free_decay", "stick_slip_belt", "bouncing_ball", "vibro_impact_gap", "friction_isolated_building",
          "elastoplastic_record", "shear_frame_bilinear"]
RTOL = 1e-8


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("stems", nargs="*", default=SCENES)
    args = parser.parse_args()
    print(f"{'scene':<28} {'samples':>7} {'events':>6} {'exact':>10} {'DOP853':>10} {'exact/DOP853':>12} "
          f"{'DOP853 off':>10}")
    ratios = []
    for stem in args.stems:
        sc = scenario.load(ROOT / "scenarios" / f"{stem}.toml")
        model, grid = build(sc), time_grid(sc.time)
        tol = Tolerances(rtol=RTOL)
        runs = {method: solve(model, grid, method, tol) for method in ("exact", "DOP853")}  # kernels loaded first
        times: dict[str, list[float]] = {"exact": [], "DOP853": []}
        for _ in range(args.repeats):
            for method in times:
                times[method].append(solve(model, grid, method, tol).stats.wall_time_s)
        exact_s, dop_s = statistics.median(times["exact"]), statistics.median(times["DOP853"])
        exact, dop = runs["exact"], runs["DOP853"]
        peak = float(np.abs(exact.displacement).max()) or 1.0
        off = float(np.abs(dop.displacement - exact.displacement).max()) / peak
        ratios.append(exact_s / dop_s)
        print(f"{stem:<28} {len(grid):7d} {len(exact.nonsmooth.events):6d} {exact_s * 1e3:7.1f} ms "
              f"{dop_s * 1e3:7.1f} ms {exact_s / dop_s:11.2f}x {off:10.1e}")
    print(f"exact/DOP853: median {statistics.median(ratios):.2f}x, worst {max(ratios):.2f}x "
          f"(below 1: exact the faster); DOP853 off: its largest difference from exact over the peak")


if __name__ == "__main__":
    main()
