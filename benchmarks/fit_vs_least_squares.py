"""Benchmark (on demand, not in CI): `smd fit` against the loop an engineer writes today: scipy's
`least_squares` (trust region reflective, its default two-point finite-difference Jacobian) around `solve_ivp`
(DOP853, rtol 1e-8) of the same frame written in numpy, on the same data, from the same start.

The scene: scenarios/three_storey_shaker.toml (storey stiffnesses and Rayleigh coefficients 30 % off), its data
made noise-free by an exact run of the true frame (the three floors' accelerations). Each fit's time (median of
--repeats), the solves it took, and its final parameter error (the largest relative error of the five estimates).

    python benchmarks/fit_vs_least_squares.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

import smdcli
from smdcli.analysis.fit import fit, make_test
from smdcli.analysis.fit_data import Measured
from smdcli.sweep.family import scenario_with

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"spring[0].k": 3.0e6, "spring[1].k": 2.4e6, "spring[2].k": 1.6e6, "damping.alpha": 0.4,
         "damping.beta": 0.002}
MASSES = np.array([2000.0, 2000.0, 1500.0])
SINES = [(500.0, 10.0), (300.0, 30.0), (200.0, 60.0)]  # on the roof: amplitude N, omega rad/s


def scipy_fit(start: np.ndarray, t: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, int]:
    """least_squares with its default finite-difference Jacobian around solve_ivp DOP853 (rtol 1e-8)."""
    M = np.diag(MASSES)
    Minv = 1.0 / MASSES
    calls = 0

    def model(p):
        nonlocal calls
        calls += 1
        k1, k2, k3, alpha, beta = p
        K = np.array([[k1 + k2, -k2, 0.0], [-k2, k2 + k3, -k3], [0.0, -k3, k3]])
        C = alpha * M + beta * K

        def rhs(time, y):
            x, v = y[:3], y[3:]
            f = np.zeros(3)
            f[2] = sum(a * np.sin(w * time) for a, w in SINES)
            return np.concatenate([v, Minv * (f - C @ v - K @ x)])

        run = solve_ivp(rhs, (0.0, t[-1]), np.zeros(6), method="DOP853", rtol=1e-8, atol=1e-12, t_eval=t)
        x, v = run.y[:3], run.y[3:]
        f = np.zeros((3, len(t)))
        f[2] = sum(a * np.sin(w * t) for a, w in SINES)
        return (Minv[:, None] * (f - C @ v - K @ x)).T  # the accelerations (N, 3)

    weights = 1.0 / np.sqrt(np.mean(measured**2, axis=0))
    scale = np.abs(start)
    found = least_squares(lambda theta: ((model(theta * scale) - measured) * weights).ravel(), start / scale,
                          bounds=(0.0, np.inf), method="trf", ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=200)
    return found.x * scale, calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    start_sc = smdcli.load(ROOT / "scenarios" / "three_storey_shaker.toml")
    truth = smdcli.simulate(scenario_with(start_sc, TRUTH), method="exact")
    data = Measured("noise-free", truth.time[1:], {f"{d}.acceleration": truth.acceleration[1:, j]
                                                   for j, d in enumerate(truth.dofs)}, {})
    want = np.array(list(TRUTH.values()))
    start = np.array([2.1e6, 3.12e6, 1.12e6, 0.52, 0.0014])
    rows = []
    for name in ("smd fit", "least_squares + solve_ivp DOP853"):
        times, error, solves = [], 0.0, 0
        for _ in range(args.repeats):
            begin = time.perf_counter()
            if name == "smd fit":
                run = fit([make_test(start_sc, data, None, None)], list(TRUTH))
                estimate, solves = run.estimate, run.solves
            else:
                estimate, solves = scipy_fit(start, data.time, np.column_stack(list(data.channels.values())))
            times.append(time.perf_counter() - begin)
            error = float(np.abs(estimate / want - 1).max())
        rows.append((name, statistics.median(times), solves, error))
    print(f"{'fit':<36} {'median':>9} {'solves':>7} {'parameter error':>16}")
    for name, seconds, solves, error in rows:
        print(f"{name:<36} {seconds:7.2f} s {solves:7d} {error:16.1e}")
    print(f"time ratio: {rows[1][1] / rows[0][1]:.0f}x (above 1: smd is faster); medians of {args.repeats}")


if __name__ == "__main__":
    main()
