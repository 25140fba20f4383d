"""Benchmark (on demand, not in CI): a constant-ductility spectrum of a 4,001-sample record (the synthetic recipe,
40 s at 100 Hz) over 100 periods (0.05 to 5 s) x 4 ductilities (1, 2, 4, 8), 5 % damping, elastoplastic: wall time
(median of repeats, in one process, kernels loaded first) and the largest deviation of the achieved ductility from
its target.

    python benchmarks/inelastic_spectrum.py [--repeats 5] [--hardening 0]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "records"))


def main() -> None:
    import make_synthetic

    from smdcli.analysis.inelastic import constant_ductility

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--hardening", type=float, default=0.0)
    args = parser.parse_args()
    make_synthetic.DURATION_S = 40.0
    t, a = make_synthetic.synthetic_record()
    a = a * 9.80665
    periods = np.geomspace(0.05, 5.0, 100)
    targets = np.array([1.0, 2.0, 4.0, 8.0])
    constant_ductility(t, a, periods[:2], [0.05], targets, args.hardening)  # kernels loaded
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        found = constant_ductility(t, a, periods, [0.05], targets, args.hardening)
        times.append(time.perf_counter() - start)
    miss = np.nanmax(np.abs(found.ductility - targets[:, None, None]) / targets[:, None, None])
    print(f"{len(t)} samples, {len(periods)} periods x {len(targets)} ductilities, 5 % damping, "
          f"{'bilinear b = %g' % args.hardening if args.hardening else 'elastoplastic'}")
    print(f"  median {statistics.median(times):.3f} s over {args.repeats} repeats (fastest {min(times):.3f} s); "
          f"strengths found {int(found.found.sum())} of {found.found.size}; largest |mu - target| / target "
          f"{miss:.1e}")


if __name__ == "__main__":
    main()
