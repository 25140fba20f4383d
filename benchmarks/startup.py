"""Benchmark (on demand, not in CI): a 1-DOF `smd simulate` against its baselines, run interleaved in one script so
that the machine's noise falls on both alike: without plots against `python -c "import numpy, h5py"`, with its
three plots against a script that saves one three-panel figure (one_figure.py). Median wall times and ratios.
Each process runs with Python's bytecode cache as a user's does (wall.as_user); smd as the console script a
user types (`python -m smdcli`, as wall.py runs it, takes 70 ms more).

    python benchmarks/startup.py [--repeats 15]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from wall import as_user

ROOT = Path(__file__).resolve().parents[1]
SCENE = str(ROOT / "scenarios" / "one_dof_underdamped.toml")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as out:
        pairs = [("smd simulate --no-plots", ["smd", "simulate", SCENE, "--no-plots", "-q", "-o", out],
                  'python -c "import numpy, h5py"', [sys.executable, "-c", "import numpy, h5py"]),
                 ("smd simulate (3 plots)", ["smd", "simulate", SCENE, "-q", "-o", out],
                  "one_figure.py (1 figure)", [sys.executable, str(ROOT / "benchmarks" / "one_figure.py"), out])]
        for ours_name, ours, base_name, base in pairs:
            _, env = as_user(base)  # the bytecode cache as a user has it; `smd` the console script a user types
            times = {ours_name: [], base_name: []}
            for command in (ours, base):  # once untimed: the bytecode and font caches written
                subprocess.run(command, env=env, check=True, capture_output=True)
            for _ in range(args.repeats):
                for name, command in ((ours_name, ours), (base_name, base)):
                    start = time.perf_counter()
                    subprocess.run(command, env=env, check=True, capture_output=True)
                    times[name].append(time.perf_counter() - start)
            ours_s, base_s = statistics.median(times[ours_name]), statistics.median(times[base_name])
            print(f"{ours_name:<26} {ours_s:6.2f} s   {base_name:<32} {base_s:6.2f} s   ratio {ours_s / base_s:4.2f}x "
                  f"(median of {args.repeats}, interleaved)")


if __name__ == "__main__":
    main()
