"""smd's default solve against scipy solve_ivp (RK45 and Radau at rtol 1e-6, the same right-hand side written
plainly in numpy) on three nonlinear scenes, in one process: median wall time, ratio, and each one's largest
displacement error against a tight reference (scipy Radau at rtol 1e-12), relative to the peak.

    python benchmarks/compiled_vs_solve_ivp.py
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances
from smdcli.solvers.run import solve_scenario

ROOT = Path(__file__).resolve().parents[1]


def chain(n: int = 100) -> str:
    """A nonlinear n-mass chain: cubic spring on the first, harmonic force, 10 s."""
    lines = ["[time]", "end = 10.0", "step = 0.01"]
    for i in range(n):
        lines += ["[[mass]]", f'name = "m{i}"', "m = 1.0"]
    lines += ["[[spring]]", 'connects = ["ground", "m0"]', "k = 100.0", 'law = "cubic"', "k3 = 1000.0"]
    for i in range(1, n):
        lines += ["[[spring]]", f'connects = ["m{i - 1}", "m{i}"]', "k = 100.0"]
    lines += ["[[damper]]", 'connects = ["ground", "m0"]', "c = 0.5"]
    lines += ["[[force]]", 'on = "m0"', 'type = "sine"', "amplitude = 10.0", "omega = 5.0"]
    return "\n".join(lines) + "\n"


def run_times(fn, repeats: int) -> tuple[list[float], object]:
    """The seconds of each of `repeats` runs of fn, and the last run's result."""
    times, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return times, out


def median_time(fn, repeats: int) -> tuple[float, object]:
    """(median seconds, last result) of `repeats` runs of fn."""
    times, out = run_times(fn, repeats)
    return statistics.median(times), out


def plain_rhs(model):
    """The scene's right-hand side written plainly: what a scipy user would pass to solve_ivp."""
    n, A, Minv = model.n, model.state_matrix, model.Minv

    def f(t, y):
        dy = A @ y
        dy[n:] += Minv @ (model.applied_force(np.array([t]))[0] - model.nonlinear_force(y[:n], y[n:]))
        return dy

    return f


def main() -> None:
    scenes = [("one_dof_nonlinear_stiff", scenario.load(ROOT / "scenarios/one_dof_nonlinear_stiff.toml")),
              ("duffing (time domain)", scenario.load(ROOT / "scenarios/duffing_frequency_response.toml")),
              ("nonlinear 100-mass chain", scenario.parse(chain(), "chain100.toml"))]
    print(f"{'scene':26} {'run':22} {'median':>10} {'ratio':>8} {'error':>9}")
    for label, sc in scenes:
        model, grid = build(sc), time_grid(sc.time)
        solve_scenario(sc, model, grid)  # kernels loaded before timing
        reference = solve(model, grid, "scipy:DOP853" if model.n > 10 else "scipy:Radau",
                          Tolerances(rtol=1e-13, atol=1e-16))
        peak = np.abs(reference.displacement).max()
        t_smd, ours = median_time(lambda: solve_scenario(sc, model, grid), 7)
        rows = [(f"smd {ours.stats.method} rtol {sc.solver.rtol:g}", t_smd,
                 np.abs(ours.displacement - reference.displacement).max() / peak)]
        y0 = np.concatenate([model.x0, model.v0])
        for method in ("RK45", "Radau"):
            repeats = 3 if method == "RK45" else 1
            extra = {"jac": lambda t, y: model.jacobian(t, y)} if method == "Radau" else {}
            t, sol = median_time(lambda: solve_ivp(plain_rhs(model), (grid[0], grid[-1]), y0, method=method,
                                                   t_eval=grid, rtol=1e-6, atol=1e-12, **extra), repeats)
            rows.append((f"solve_ivp {method} rtol 1e-6", t,
                         np.abs(sol.y[:model.n].T - reference.displacement).max() / peak))
        for name, t, err in rows:
            print(f"{label:26} {name:22} {t * 1e3:8.1f} ms {t / t_smd:7.1f}x {err:9.1e}")


if __name__ == "__main__":
    main()
