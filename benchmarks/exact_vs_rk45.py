"""Benchmark (on demand, not in CI): exact against scipy solve_ivp(RK45) on three_dof_forced, 0..120 s.

Times both in one process, interleaved, and prints medians, the speed ratio,
and both errors against a tight DOP853 reference (rtol 1e-12, restarted at
the step force's edge at t = 0, which is the start).

    python benchmarks/exact_vs_rk45.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    sc = scenario.load(ROOT / "scenarios" / "three_dof_forced.toml")
    model = build(sc)
    grid = time_grid(sc.time)
    y0 = np.concatenate([model.x0, model.v0])

    def rhs(t, y):
        return model.state_matrix @ y + model.input_matrix @ model.forces(t)

    def run_exact():
        return solve(model, grid, "exact", Tolerances()).displacement

    def run_rk45():
        return solve_ivp(rhs, (grid[0], grid[-1]), y0, method="RK45", t_eval=grid, rtol=1e-6, atol=1e-9).y[:3].T

    ref = solve_ivp(rhs, (grid[0], grid[-1]), y0, method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-14).y[:3].T
    peak = np.abs(ref).max()
    times = {"exact": [], "RK45": []}
    results = {}
    for _ in range(args.repeats):
        for name, fn in (("exact", run_exact), ("RK45", run_rk45)):
            start = time.perf_counter()
            results[name] = fn()
            times[name].append(time.perf_counter() - start)
    med = {k: statistics.median(v) for k, v in times.items()}
    err = {k: np.abs(results[k] - ref).max() for k in results}
    print(f"three_dof_forced, 0..120 s, {len(grid)} points, {args.repeats} repeats, peak |x| {peak:.4f} m")
    for name in ("exact", "RK45"):
        print(f"  {name:6s} median {med[name] * 1e3:9.2f} ms   max abs error {err[name]:.2e} m "
              f"({err[name] / peak:.1e} of peak)")
    print(f"  speed ratio RK45/exact: {med['RK45'] / med['exact']:.0f}x;  "
          f"error ratio RK45/exact: {err['RK45'] / max(err['exact'], 1e-300):.0f}x")
    print("  (the reference's own error bounds how small the exact error can be shown to be)")


if __name__ == "__main__":
    main()
