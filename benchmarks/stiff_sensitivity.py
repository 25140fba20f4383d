"""Benchmark (on demand, not in CI): a smooth scene's sensitivities as its law stiffens, by the explicit kernel alone
and as `smd sensitivity` runs them (DOP853, handed to Radau IIA where Hairer's test finds the steps stability's and
below a hundredth of the output step).

The scene is tests/test_sensitivity.py's two masses, the second on a belt through a tanh friction (F = 0.8 N,
m = 0.5 kg) over 3 s: F / (m r) grows from 160 to 1.6e7 per second as the regularization r falls from 1e-2 to 1e-6
m/s. Two parameters (the first spring's k and the friction's force), rtol 1e-9; median wall times of each way, one
process, and smdcli.simulate's (auto: Radau at rtol 1e-6) beside them.

    python benchmarks/stiff_sensitivity.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import smdcli
from smdcli.scenario import parse
from smdcli.solvers import sensitivity_run

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_sensitivity import REGULARIZED  # noqa: E402  (the scene the tests check against the complex step)

PARAMS = ["spring[0].k", "friction[0].force"]
EXPLICIT_UP_TO = 1e-6  # below, DOP853 alone takes ten times as long for each tenth of r: not timed


def median_time(call, repeats: int) -> float:
    """The median wall time of call() over repeats, after a warm-up call."""
    call()
    times = []
    for _ in range(repeats):
        begin = time.perf_counter()
        call()
        times.append(time.perf_counter() - begin)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"{'r (m/s)':>8} {'F/(m r)':>9} {'DOP853 alone':>13} {'smd sensitivity':>16}  {'kernel':<7} {'simulate':>9}")
    for r in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7):
        sc = parse(REGULARIZED.replace("regularization = 1e-3", f"regularization = {r!r}"), "stiff.toml")
        sensitivity_run.KERNEL = "explicit"
        alone = median_time(lambda: smdcli.sensitivity(sc, PARAMS), args.repeats) if r >= EXPLICIT_UP_TO else None
        sensitivity_run.KERNEL = None
        chosen = median_time(lambda: smdcli.sensitivity(sc, PARAMS), args.repeats)
        kernel = "Radau" if "Radau" in smdcli.sensitivity(sc, PARAMS).method else "DOP853"
        run = median_time(lambda: smdcli.simulate(sc), args.repeats)
        shown = f"{alone * 1e3:10.0f} ms" if alone is not None else f"{'-':>13}"
        print(f"{r:8.0e} {0.8 / (0.5 * r):9.2g} {shown} {chosen * 1e3:13.0f} ms  {kernel:<7} {run * 1e3:6.1f} ms")
    print(f"(medians of {args.repeats}; k and the friction's force at rtol 1e-9; simulate: auto at its rtol 1e-6)")


if __name__ == "__main__":
    main()
