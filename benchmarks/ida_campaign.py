"""Benchmark (on demand, not in CI): the issue's IDA campaign, 20 records x 12 fill runs of the 3-storey yielding
frame (scenarios/ida_frame.toml), --no-plots, on the local process pool; the wall time and the runs, against the
bar of 30 s on 2 cores. The 20 records are made like records/suite's (records/make_record_suite.py's synthetic
noise), written to a temporary folder as two-column CSV in g.

    python benchmarks/ida_campaign.py [--records 20] [--workers 2]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    spec = importlib.util.spec_from_file_location("suite", ROOT / "records" / "make_record_suite.py")
    suite = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(suite)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "records"
        folder.mkdir()
        for seed in range(1, args.records + 1):
            dt, g = suite.synthetic(seed)
            rows = [f"{dt * i:.4f},{a:.7f}" for i, a in enumerate(g)]
            (folder / f"record_{seed:02d}.csv").write_text("time_s,acceleration_g\n" + "\n".join(rows) + "\n")
        begin = time.perf_counter()
        ran = subprocess.run([sys.executable, "-m", "smdcli", "ida", str(ROOT / "scenarios" / "ida_frame.toml"),
                              "--records", str(folder), "--runs", "12", "--workers", str(args.workers),
                              "--no-plots", "--json", "-o", str(Path(tmp) / "out")], capture_output=True, text=True)
        wall = time.perf_counter() - begin
    if ran.returncode != 0:
        raise SystemExit(ran.stderr)
    data = json.loads(ran.stdout)
    runs = np.array([r["runs"] for r in data["records"]])
    print(f"{len(runs)} records, {runs.sum()} runs ({runs.min()}..{runs.max()} a record), {args.workers} workers: "
          f"wall {wall:.1f} s ({wall / runs.sum() * args.workers:.3f} s a run a worker); bar 30 s: "
          f"{'met' if wall < 30 else 'not met'}")


if __name__ == "__main__":
    main()
