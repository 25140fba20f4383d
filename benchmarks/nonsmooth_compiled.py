"""smd's compiled ODE methods on nonsmooth scenes (each mode in a compiled kernel, Python only at events) against
the same method stepped from Python (scipy's OdeSolver through the same modes and decisions), in one
process: median wall time, ratio, and the largest difference of the two histories relative to the peak.

    python benchmarks/nonsmooth_compiled.py [--repeats 5]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from compiled_vs_solve_ivp import median_time

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

ROOT = Path(__file__).resolve().parents[1]
SCENES = [("coulomb_free_decay", "DOP853"), ("bouncing_ball", "DOP853"), ("stick_slip_belt", "DOP853"),
          ("vibro_impact_gap", "DOP853"), ("bouc_wen_multisine", "DOP853"), ("elastoplastic_record", "RK45"),
          ("shear_frame_bilinear", "RK45"), ("friction_isolated_building", "DOP853"), ("bouc_wen_multisine", "Radau"),
          ("stick_slip_belt", "Radau"), ("stick_slip_belt", "ode15s"), ("stick_slip_belt", "ode23s"),
          ("stick_slip_belt", "ode23t"), ("stick_slip_belt", "ode23tb")]
REFERENCE = {"ode15s": "scipy:BDF"}  # the scipy-driven class of each compiled method (else scipy:METHOD)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"{'scene':<28} {'method':<7} {'events':>6} {'compiled':>10} {'from Python':>12} {'ratio':>7} {'difference':>10}")
    for stem, method in SCENES:
        sc = scenario.load(ROOT / "scenarios" / f"{stem}.toml")
        model, grid = build(sc), time_grid(sc.time)
        tol = Tolerances(rtol=sc.solver.rtol, atol=sc.solver.atol)
        solve(model, grid, method, tol)  # the kernel loaded before the clock
        ours_s, ours = median_time(lambda: solve(model, grid, method, tol), args.repeats)
        theirs_s, theirs = median_time(lambda: solve(model, grid, REFERENCE.get(method, f"scipy:{method}"), tol), max(1, args.repeats // 2))
        peak = np.abs(theirs.displacement).max()
        difference = np.abs(ours.displacement - theirs.displacement).max() / peak
        print(f"{stem:<28} {method:<7} {len(ours.nonsmooth.events):6d} {ours_s * 1e3:7.1f} ms {theirs_s * 1e3:9.1f} ms "
              f"{theirs_s / ours_s:6.0f}x {difference:10.1e}")
    print("ratio: from Python / compiled, each at the scenario's tolerances; difference: max |x - x_python| / peak")


if __name__ == "__main__":
    main()
