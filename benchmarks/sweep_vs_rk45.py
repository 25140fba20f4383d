"""Benchmark (on demand, not in CI): a sweep of 10,000 linear 1-DOF members against a loop of
scipy solve_ivp(RK45), per member, in one process.

Each member is m x'' + c x' + k x = 10 sin(3 t) from x0 = 0.1, 0..10 s on 1001 output points,
with (k, c) over a 100 x 100 grid (k 5..50 N/m, c 0.1..12 N s/m), so under-, critically and
over-damped members are all in it. The sweep is timed whole, from the scenario to the stacked
displacement and velocity of every member (smd's batched exact recurrence); acceleration,
which smd derives on demand, is timed apart. RK45 (rtol 1e-6, atol 1e-9, t_eval on the grid)
runs over a sample of members. Both are scored against the closed form of each sampled member
(undamped, under-, critically or over-damped transient plus the harmonic steady state).

    python benchmarks/sweep_vs_rk45.py [--members 10000] [--sample 40] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy.integrate import solve_ivp

from smdcli import scenario
from smdcli.model import time_grid
from smdcli.sweep import build_family, read_spec, solve_family

TEXT = """
[time]
end = 10.0
points = 1001
[[mass]]
name = "m"
m = 1.0
x0 = 0.1
[[spring]]
connects = ["ground", "m"]
k = 25.0
[[damper]]
connects = ["ground", "m"]
c = 1.0
[[force]]
on = "m"
type = "sine"
amplitude = 10.0
omega = 3.0
"""
F0, W, X0 = 10.0, 3.0, 0.1


def closed_form(k: float, c: float, t: np.ndarray) -> np.ndarray:
    """x(t) of x'' + c x' + k x = F0 sin(W t), x(0) = X0, x'(0) = 0: steady state plus the free transient."""
    H = 1.0 / (k - W**2 + 1j * W * c)
    xs = lambda tt: (F0 * H * np.exp(1j * W * tt)).imag  # noqa: E731
    vs0 = (F0 * H * 1j * W).imag
    a, b = X0 - xs(0.0), 0.0 - vs0  # the transient's initial displacement and velocity
    wn, zeta = np.sqrt(k), c / (2 * np.sqrt(k))
    if abs(zeta - 1) < 1e-12:
        free = (a + (b + wn * a) * t) * np.exp(-wn * t)
    elif zeta < 1:
        wd = wn * np.sqrt(1 - zeta**2)
        free = np.exp(-zeta * wn * t) * (a * np.cos(wd * t) + (b + zeta * wn * a) / wd * np.sin(wd * t))
    else:
        s = wn * np.sqrt(zeta**2 - 1)
        r1, r2 = -zeta * wn - s, -zeta * wn + s
        A = (b - r2 * a) / (r1 - r2)
        free = A * np.exp(r1 * t) + (a - A) * np.exp(r2 * t)
    return xs(t) + free


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--members", type=int, default=10_000)
    parser.add_argument("--sample", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    side = int(round(np.sqrt(args.members)))
    sc = scenario.parse(TEXT, "benchmark.toml")
    spec = read_spec(sc, {"parameter": ("spring[0].k", "damper[0].c"),
                          "values": (f"linspace(5, 50, {side})", f"linspace(0.1, 12, {side})")})
    grid = time_grid(sc.time)

    def run_sweep():
        family = build_family(sc, spec)
        return family, solve_family(family)

    rng = np.random.default_rng(0)
    family, result = run_sweep()  # warm-up: imports and first-call costs
    S = len(family)
    sample = rng.choice(S, size=min(args.sample, S), replace=False)

    def run_rk45(s):
        k, c = family.values[s]
        rhs = lambda t, y: [y[1], F0 * np.sin(W * t) - c * y[1] - k * y[0]]  # noqa: E731
        return solve_ivp(rhs, (0.0, 10.0), [X0, 0.0], method="RK45", t_eval=grid, rtol=1e-6, atol=1e-9).y[0]

    sweep_times, accel_times, rk_times = [], [], []
    del family, result  # a repeat recycles the memory the last one freed, as a process running many sweeps does
    start = time.perf_counter()
    family, result = run_sweep()
    cold = time.perf_counter() - start
    for _ in range(args.repeats):
        del family, result
        start = time.perf_counter()
        family, result = run_sweep()
        sweep_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        result.acceleration
        accel_times.append(time.perf_counter() - start)
        start = time.perf_counter()
        for s in sample:
            run_rk45(s)
        rk_times.append((time.perf_counter() - start) / len(sample))
    errors_smd, errors_rk = [], []
    for s in sample:
        k, c = family.values[s]
        exact = closed_form(k, c, grid)
        peak = np.abs(exact).max()
        errors_smd.append(np.abs(result.displacement[s, :, 0] - exact).max() / peak)
        errors_rk.append(np.abs(run_rk45(s) - exact).max() / peak)
    per_member = statistics.median(sweep_times) / S
    with_accel = (statistics.median(sweep_times) + statistics.median(accel_times)) / S
    rk = statistics.median(rk_times)
    print(f"{S} linear 1-DOF members, 0..10 s, {len(grid)} points; {result.how}; {args.repeats} repeats")
    print(f"  smd sweep      {per_member * 1e6:8.2f} us per member (median; whole sweep "
          f"{statistics.median(sweep_times) * 1e3:.0f} ms), with acceleration {with_accel * 1e6:.2f} us")
    print(f"  first sweep    {cold / S * 1e6:8.2f} us per member (the first touch of {result.displacement.nbytes * 2 / 2**20:.0f} MB "
          "of fresh result memory; costly on some machines)")
    print(f"  RK45 loop      {rk * 1e6:8.0f} us per member (median over {len(sample)} sampled members)")
    print(f"  speed ratio    {rk / per_member:8.0f}x per member ({rk / with_accel:.0f}x with acceleration)")
    print(f"  error / peak against the closed form, worst of the sample: smd {max(errors_smd):.1e}, "
          f"RK45 {max(errors_rk):.1e}")


if __name__ == "__main__":
    main()
