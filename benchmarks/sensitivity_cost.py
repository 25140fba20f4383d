"""Benchmark (on demand, not in CI): what P sensitivities cost, in forward runs of the same scene.

A finite difference takes P + 1 runs of the scene, each built at its parameter values and solved; `smd
sensitivity` must cost less. For each scene: the median wall time of `smdcli.sensitivity(scene, params)` (all of it:
the model's derivatives, the solve, the peaks and their derivatives, the result) and of one forward run (the scene
built from its scenario and solved on the same grid by the same solver, with its result), in one process,
interleaved, after a warm-up of each (the forward run with BLAS on one thread where the scene is small, as the
sensitivities run it); their ratio against P + 1.

    python benchmarks/sensitivity_cost.py [--repeats 15]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import smdcli
from smdcli.analysis.sensitivity import _forward_time
from smdcli.resources import small_blas

ROOT = Path(__file__).resolve().parents[1]
SCENES = [  # (scenario, its parameters)
    ("two_dof_forced", ["spring[0].k", "spring[1].k", "mass.m1.m", "damper[1].c"]),
    ("three_dof_forced", ["spring[0].k", "spring[2].k", "damper[0].c"]),
    ("three_storey_shaker", ["spring[0].k", "spring[1].k", "spring[2].k", "damping.alpha", "damping.beta"]),
    ("five_storey_building", ["spring[0].k", "spring[4].k", "mass[2].m"]),
    ("elastoplastic_record", ["spring[0].k", "spring[0].fy"]),
    ("stick_slip_belt", ["friction[0].force", "friction[0].static", "spring[0].k"]),
    ("vibro_impact_gap", ["stop[0].restitution", "spring[0].k"]),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print(f"{'scene':<22} {'P':>2} {'sensitivity':>12} {'forward run':>12} {'ratio':>7} {'P + 1':>6}")
    for name, params in SCENES:
        sc = smdcli.load(ROOT / "scenarios" / f"{name}.toml")
        found = smdcli.sensitivity(sc, params)  # warm-up: imports, compiled kernels' loading
        _forward_time(sc, found.time)
        whole, forward = [], []
        for _ in range(args.repeats):
            begin = time.perf_counter()
            smdcli.sensitivity(sc, params)
            whole.append(time.perf_counter() - begin)
            with small_blas(2 * len(sc.dof_names)):  # at its best: BLAS as the sensitivities run it, one thread on a small scene
                forward.append(_forward_time(sc, found.time))
        s, f = statistics.median(whole), statistics.median(forward)
        print(f"{name:<22} {len(params):>2} {s * 1e3:9.1f} ms {f * 1e3:9.2f} ms {s / f:6.1f}x {len(params) + 1:>6}")
    print(f"(medians of {args.repeats}, interleaved; ratio: the sensitivities' time over one forward run's; a "
          "finite difference takes P + 1 runs)")


if __name__ == "__main__":
    main()
