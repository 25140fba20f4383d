"""Benchmark (on demand, not in CI): where auto gives a sparse scene to the Taylor series and where to sparse Newmark.

Chains fixed at one end (1 kg a mass, k and c a link, a 10 N sine force at 5 rad/s on the first mass; 10 s on 1,001
points, rtol 1e-6), their M, C and K in Matrix Market files, each solved by `taylor` and by `sparse_newmark` in one
process (each run once untimed, then the median of --repeats, the whole of smdcli.simulate). `steps/out`: the fewest
steps an output step stability allows the series (Gershgorin's bound on |lambda| times the output step over the
series' stability boundary), auto's measure: it takes the series up to SPARSE_TAYLOR_STEPS. error: the largest
displacement difference from the Taylor series at rtol 1e-12 (its own error some 1e-13), over the peak.

    python benchmarks/sparse_choice.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import smdcli
from smdcli.model import build
from smdcli.model.sparse import gershgorin_rate
from smdcli.solvers.auto import SPARSE_TAYLOR_STEPS
from smdcli.solvers.integrators.taylor_series import taylor_boundary, taylor_order

sys.path.insert(0, str(Path(__file__).resolve().parent))
from wall import chain_files  # noqa: E402

CHAINS = [(5000, 1e6, 0.5), (5000, 1e4, 50.0), (5000, 1e5, 500.0), (5000, 3.6e5, 1800.0), (5000, 1e6, 5000.0)]


def scene(folder: Path, n: int, k: float, c: float) -> Path:
    """The chain's scenario, its matrices beside it (wall.chain_files' chain with its links' k and c)."""
    text = chain_files(n, "every", str(folder))
    import scipy.io

    for key, value, unit in (("K", k, 100.0), ("C", c, 0.5)):
        path = folder / f"chain_{key}.mtx"
        scipy.io.mmwrite(path, scipy.io.mmread(path) * (value / unit), symmetry="symmetric")
    path = folder / "chain.toml"
    path.write_text(text)
    return path


def timed(path: Path, method: str, repeats: int):
    """(median seconds of the solve, the run) of a method on a scene."""
    runs, times = [], []
    for _ in range(repeats + 1):
        start = time.perf_counter()
        run = smdcli.simulate(path, method=method)
        times.append(time.perf_counter() - start)
        runs.append(run)
    return statistics.median(times[1:]), runs[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{'chain':34s} {'steps/out':>9s} {'auto':>14s} {'taylor':>9s} {'error':>8s} {'sparse_newmark':>14s} "
          f"{'error':>8s}")
    with tempfile.TemporaryDirectory() as folder:
        for n, k, c in CHAINS:
            root = Path(folder) / f"{n}_{k:g}_{c:g}"
            root.mkdir()
            path = scene(root, n, k, c)
            reference = smdcli.simulate(path, method="taylor", rtol=1e-12).displacement
            chosen = smdcli.simulate(path).stats
            model = build(smdcli.load(path))
            steps = gershgorin_rate(model) * 0.01 / taylor_boundary(taylor_order(1e-6))
            cells = []
            for method in ("taylor", "sparse_newmark"):
                try:
                    seconds, run = timed(path, method, args.repeats)
                except smdcli.SolverFailed:
                    cells.append(f"{'failed':>9s} {'':>8s}")
                    continue
                error = np.abs(run.displacement - reference).max() / np.abs(reference).max()
                cells.append(f"{seconds:8.2f}s {error:8.1e}")
            name = f"{n} masses, k {k:g}, c {c:g}"
            print(f"{name:34s} {steps:9.2g} {chosen.method:>14s} {cells[0]} {cells[1]:>23s}")
    print(f"(auto takes the series up to {SPARSE_TAYLOR_STEPS} steps an output step; medians of {args.repeats})")


if __name__ == "__main__":
    main()
