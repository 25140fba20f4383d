"""Benchmark (on demand, not in CI): what P sensitivities cost, in forward runs of the same scene.

A finite difference takes P + 1 runs of the scene, each built at its parameter values and solved; `smd
sensitivity` must cost less, whichever way it is compared:

- histories: `smdcli.sensitivity(scene, params, peaks=False)` (the model's derivatives, the solve and the result:
  what a fit takes) against one forward run (the scene built from its scenario and solved on the same grid by the
  same solver, with its result);
- with the peaks: the whole of `smdcli.sensitivity` (also each DOF's peak located between samples and its
  derivative) against that forward run with its peaks located (a difference of the peaks needs each run's);
- against the API: the whole of `smdcli.sensitivity` against `smdcli.simulate` (the run a finite difference through
  smd's API takes: the solve with the element forces and the energy balance smd attaches to every run).

The last rows are classically damped chains (wall.chain's), whose forward run is output-bound: each sensitivity
has an output of its own and a coupling to the scene's state on top (its equations are driven by dA/dp x). From 64
stacked DOFs ((P + 1) n) they are solved in modal coordinates (analysis/modal_sensitivity.py); below, by the dense
stacked system, where the outputs' cost can outweigh the fixed cost a run shares. Then chains damped at their free end
alone, which no modes decouple: the stacked system by its arrow structure where that is estimated to cost less
(solvers/exact/arrow.py), by the sparse action from a few hundred DOFs.

Median wall times in one process, interleaved, after a warm-up of each (the forward run with BLAS on one thread
where the scene is small, as the sensitivities run it); the ratios against P + 1.

    python benchmarks/sensitivity_cost.py [--repeats 15]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import smdcli
from smdcli.analysis.sensitivity import sensitivity
from smdcli.analysis.sensitivity_cost import forward_time
from smdcli.resources import small_blas

ROOT = Path(__file__).resolve().parents[1]
SCENES = [  # (scenario, its parameters)
    ("one_dof_underdamped", ["spring[0].k"]),
    ("ic_critical", ["mass[0].m"]),
    ("one_dof_harmonic", ["force[0].amplitude"]),
    ("two_dof_forced", ["spring[0].k", "spring[1].k", "mass.m1.m", "damper[1].c"]),
    ("three_dof_forced", ["spring[0].k", "spring[2].k", "damper[0].c"]),
    ("three_dof_forced", ["spring[0].k", "spring[1].k", "spring[2].k", "spring[3].k", "damper[0].c",
                          "damper[1].c", "mass.m1.m", "mass.m2.m"]),
    ("three_storey_shaker", ["spring[0].k", "spring[1].k", "spring[2].k", "damping.alpha", "damping.beta"]),
    ("five_storey_building", ["spring[0].k", "spring[4].k", "mass[2].m"]),
    ("five_storey_tmd", ["spring[0].k", "spring[5].k", "damper[0].c"]),
    ("shear_frame_record", ["spring[0].k", "mass[1].m"]),
    ("quarter_car_bump", ["spring[0].k", "damper[0].c"]),
    ("elastoplastic_record", ["spring[0].fy"]),
    ("elastoplastic_record", ["spring[0].k", "spring[0].fy"]),
    ("coulomb_free_decay", ["friction[0].force"]),
    ("coulomb_free_decay", ["spring[0].k"]),
    ("stick_slip_belt", ["friction[0].force", "friction[0].static", "spring[0].k"]),
    ("vibro_impact_gap", ["stop[0].restitution", "spring[0].k"]),
    # a force's frequency (its derivative a signal of its own, t cos wt) and a record's scale
    ("one_dof_harmonic", ["force[0].omega"]),
    ("two_dof_forced", ["force[0].omega"]),
    ("three_dof_forced", ["force[0].omega"]),
    ("five_storey_building", ["ground_motion.scale"]),
    ("shear_frame_record", ["ground_motion.scale"]),
    # wall.chain's: a classically damped chain, whose forward run is output-bound (its cost grows as the output)
    ("chain of 10 masses", ["spring[0].k"]),
    ("chain of 30 masses", ["spring[0].k"]),
    ("chain of 30 masses", ["spring[0].k", "damper[0].c"]),
    # from 64 DOFs the forward run of a classically damped scene is in modal coordinates, and from 64 stacked DOFs
    # ((P + 1) n) its sensitivities too
    ("chain of 100 masses", ["spring[0].k"]),
    ("chain of 100 masses", ["spring[0].k", "damper[50].c", "mass.m99.m"]),
    ("chain of 300 masses", ["spring[0].k"]),
    # from about 50 masses an element's or a mass's coupling of the modes is a product of thin factors
    ("chain of 600 masses", ["spring[0].k", "damper[300].c", "mass.m599.m"]),
    # damped at its free end only: no modes decouple it; its stacked system's exponential by its arrow structure
    # (solvers/exact/arrow.py) from about 160 stacked states, the sparse action's from a few hundred DOFs
    ("chain of 30 masses damped at its end", ["spring[0].k"]),
    ("chain of 30 masses damped at its end", ["spring[0].k", "mass.m1.m"]),
    ("chain of 63 masses damped at its end", ["spring[0].k"]),
    ("chain of 63 masses damped at its end", ["spring[0].k", "mass.m1.m"]),
    ("chain of 100 masses damped at its end", ["spring[0].k", "mass.m1.m"]),
]


def _scene(name: str):
    """A bundled scenario by stem, or wall.chain's n-mass chain ("chain of n masses", a damper on every spring, or
    "... damped at its end", one at its free end)."""
    if not name.startswith("chain of "):
        return smdcli.load(ROOT / "scenarios" / f"{name}.toml")
    from smdcli.scenario import parse
    from wall import chain

    damper = "end" if name.endswith("damped at its end") else "every"
    return parse(chain(int(name.split()[2]), False, damper), f"{name.replace(' ', '_')}.toml")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print(f"{'scene':<37} {'P':>2} {'histories':>10} {'run':>9} {'ratio':>6}   {'with peaks':>10} {'run':>9} "
          f"{'ratio':>6}   {'simulate':>9} {'ratio':>6} {'P + 1':>6}")
    for name, params in SCENES:
        sc = _scene(name)
        found = smdcli.sensitivity(sc, params)  # warm-up: imports, compiled kernels' loading
        forward_time(sc, found.time)
        smdcli.simulate(sc)
        histories, whole, forward, with_peaks, api = [], [], [], [], []
        for _ in range(args.repeats):
            begin = time.perf_counter()
            sensitivity(sc, params, peaks=False)
            histories.append(time.perf_counter() - begin)
            begin = time.perf_counter()
            smdcli.sensitivity(sc, params)
            whole.append(time.perf_counter() - begin)
            # at its best: BLAS as the sensitivities run it, one thread on a small scene
            with small_blas(2 * len(sc.dof_names)):
                forward.append(forward_time(sc, found.time))
                with_peaks.append(forward_time(sc, found.time, peaks=True))
            begin = time.perf_counter()
            smdcli.simulate(sc)
            api.append(time.perf_counter() - begin)
        h, s, f, p, a = (statistics.median(q) for q in (histories, whole, forward, with_peaks, api))
        print(f"{name:<37} {len(params):>2} {h * 1e3:7.1f} ms {f * 1e3:6.2f} ms {h / f:5.2f}x   {s * 1e3:7.1f} ms "
              f"{p * 1e3:6.2f} ms {s / p:5.2f}x   {a * 1e3:6.2f} ms {s / a:5.2f}x {len(params) + 1:>6}")
    print(f"(medians of {args.repeats}, interleaved; histories: the sensitivities without the peaks against a forward "
          "run; with peaks: with them, against a forward run and its located peaks; simulate: the whole against "
          "smdcli.simulate; a finite difference takes P + 1 runs)")


if __name__ == "__main__":
    main()
