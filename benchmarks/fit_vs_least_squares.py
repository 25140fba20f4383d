"""Benchmark (on demand, not in CI): `smd fit` against the loop an engineer writes today: scipy's
`least_squares` (trust region reflective, its default two-point finite-difference Jacobian) around `solve_ivp`
(DOP853, rtol 1e-8) of the same frame written in numpy, on the same data, from the same start.

The scene: scenarios/three_storey_shaker.toml (storey stiffnesses and Rayleigh coefficients 30 % off), its data
made noise-free by an exact run of the true frame (the three floors' accelerations). Each fit's time (median of
--repeats), the solves it took, and its final parameter error (the largest relative error of the five estimates).

With --bouc-wen: the Bouc-Wen benchmark's physical model (scenarios/bouc_wen_benchmark.toml: k, alpha, beta, gamma
and c, each started 10 % off) on the first --window seconds of its own multisine, the data its displacement by a
DOP853 run at rtol 1e-12 of the true scene; scipy's side the same law written in numpy, the force table read by
np.interp, at rtol 1e-8 and again at 1e-12 (at 1e-8 and 1e-10 its differences stall the fit short of the truth).

    python benchmarks/fit_vs_least_squares.py [--repeats 3] [--bouc-wen [--window 0.3]]
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
BOUC_WEN = {"spring[0].k": 1.0e5, "spring[0].alpha": 0.5, "spring[0].beta": 800.0, "spring[0].gamma": -1100.0,
            "damper[0].c": 10.0}
BOUC_WEN_START = np.array([1.1, 0.9, 1.1, 0.9, 1.1])  # times the truth


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


def scipy_bouc_wen_fit(start: np.ndarray, t: np.ndarray, measured: np.ndarray, force: tuple, rtol: float) -> tuple:
    """least_squares with its default finite-difference Jacobian around solve_ivp DOP853 (at rtol) of
    m x'' + c x' + alpha k x + (1 - alpha) k z = F(t), z' = x' - beta |x'| z - gamma x' |z| (A = n = 1, m = 2 kg)."""
    calls = 0
    table_t, table_f = force

    def model(p):
        nonlocal calls
        calls += 1
        k, alpha, beta, gamma, c = p

        def rhs(time, y):
            x, v, z = y
            f = np.interp(time, table_t, table_f)
            return [v, (f - c * v - alpha * k * x - (1 - alpha) * k * z) / 2.0,
                    v - beta * abs(v) * z - gamma * v * abs(z)]

        return solve_ivp(rhs, (0.0, t[-1]), np.zeros(3), method="DOP853", rtol=rtol, atol=1e-4 * rtol,
                         t_eval=t).y[0]

    scale = np.abs(start)
    weight = 1.0 / np.sqrt(np.mean(measured**2))
    found = least_squares(lambda theta: (model(theta * scale) - measured) * weight, start / scale, method="trf",
                          ftol=1e-12, xtol=1e-12, gtol=1e-12, max_nfev=200)
    return found.x * scale, calls


def bouc_wen_rows(repeats: int, window: float) -> list:
    """(name, median seconds, solves, parameter error) of both fits of the Bouc-Wen benchmark's model."""
    from smdcli.model import build

    sc = scenario_with(smdcli.load(ROOT / "scenarios" / "bouc_wen_benchmark.toml"), {"time.end": window})
    truth = smdcli.simulate(sc, method="DOP853", rtol=1e-12, atol=1e-16)
    data = Measured("noise-free", truth.time[1:], {"m.displacement": truth.displacement[1:, 0]}, {})
    want = np.array(list(BOUC_WEN.values()))
    start = want * BOUC_WEN_START
    started = scenario_with(sc, dict(zip(BOUC_WEN, start)))
    table = build(sc).signals[0]
    rows = []
    for name, rtol in (("smd fit", None), ("least_squares + DOP853 rtol 1e-8", 1e-8),
                       ("least_squares + DOP853 rtol 1e-12", 1e-12)):
        times, error, solves = [], 0.0, 0
        for _ in range(repeats):
            begin = time.perf_counter()
            if rtol is None:
                run = fit([make_test(started, data, None, None)], list(BOUC_WEN))
                estimate, solves = run.estimate, run.solves
            else:
                estimate, solves = scipy_bouc_wen_fit(start, data.time, data.channels["m.displacement"],
                                                      (table.t, table.v), rtol)
            times.append(time.perf_counter() - begin)
            error = float(np.abs(estimate / want - 1).max())
        rows.append((name, statistics.median(times), solves, error))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--bouc-wen", action="store_true", help="the Bouc-Wen benchmark's model, not the frame")
    parser.add_argument("--window", type=float, default=0.3, help="seconds of the Bouc-Wen multisine fitted")
    args = parser.parse_args()
    if args.bouc_wen:
        report(bouc_wen_rows(args.repeats, args.window), args.repeats)
        return
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
    report(rows, args.repeats)


def report(rows: list, repeats: int) -> None:
    """The two fits' table and their time ratio."""
    print(f"{'fit':<36} {'median':>9} {'solves':>7} {'parameter error':>16}")
    for name, seconds, solves, error in rows:
        print(f"{name:<36} {seconds:7.2f} s {solves:7d} {error:16.1e}")
    for name, seconds, _, _ in rows[1:]:
        print(f"time ratio to {name}: {seconds / rows[0][1]:.0f}x (above 1: smd is faster)")
    print(f"medians of {repeats}")


if __name__ == "__main__":
    main()
