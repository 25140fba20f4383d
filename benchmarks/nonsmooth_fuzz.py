"""Random small nonsmooth scenes (1-3 masses; elastoplastic and bilinear springs, dampers, Coulomb friction and
rigid stops between random pairs, a sine force) solved by `exact` and by DOP853 and Radau at rtol 1e-11: prints
each scene where a run fails, where exact's energy balance is off by more than 1e-10, or where exact and both
integrators disagree by more than 1e-6 of the peak while the integrators agree with each other, and writes it
to OUT/fuzz_SEED_TRIAL.toml. A finder of cases for tests, not a test: run on demand.

    python benchmarks/nonsmooth_fuzz.py [--seed 1] [--trials 25] [--out fuzz] [--wide]
"""

from __future__ import annotations

import argparse
import random
from pathlib import Path

import numpy as np

from smdcli import scenario
from smdcli.analysis.energy import with_physics
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances


def random_scene(rng: random.Random, wide: bool = False) -> str:
    """A scene of 1-3 masses in a chain to ground, with random hysteretic springs, friction contacts and stops;
    wide, also breakaway forces above the kinetic ones, belts under ground contacts and a ground motion."""
    n = rng.choice([1, 2, 3])
    names = [f"m{i}" for i in range(n)]
    nodes = ["ground", *names]
    lines = ["[time]", "end = 4.0", "step = 0.01"]
    for name in names:
        lines += ["[[mass]]", f'name = "{name}"', f"m = {rng.uniform(0.5, 2):.3f}", f"v0 = {rng.uniform(-0.5, 0.5):.3f}"]
    for i in range(n):
        lines += ["[[spring]]", f'connects = ["{nodes[i]}", "{nodes[i + 1]}"]', f"k = {rng.uniform(50, 400):.1f}"]
        if rng.random() < 0.4:
            lines += ['law = "elastoplastic"' if rng.random() < 0.5 else 'law = "bilinear"\nhardening = 0.1',
                      f"fy = {rng.uniform(1, 5):.2f}"]
        if rng.random() < 0.5:
            lines += ["[[damper]]", f'connects = ["{nodes[i]}", "{nodes[i + 1]}"]', f"c = {rng.uniform(0.1, 2):.2f}"]
    for _ in range(rng.choice([1, 2])):
        a, b = rng.sample(nodes, 2)
        if rng.random() < 0.5:
            force = rng.uniform(0.2, 2)
            lines += ["[[friction]]", f'connects = ["{a}", "{b}"]', f"force = {force:.2f}"]
            if wide and rng.random() < 0.5:
                lines += [f"static = {force * rng.uniform(1.0, 1.5):.2f}"]
            if wide and "ground" in (a, b) and rng.random() < 0.4:
                lines += [f"belt_velocity = {rng.uniform(-0.2, 0.2):.3f}"]
        else:
            lines += ["[[stop]]", f'connects = ["{a}", "{b}"]', f"max = {rng.uniform(0.01, 0.05):.3f}",
                      f"min = {-rng.uniform(0.01, 0.05):.3f}", f"restitution = {rng.uniform(0, 0.9):.2f}"]
    lines += ["[[force]]", f'on = "{rng.choice(names)}"', 'type = "sine"', f"amplitude = {rng.uniform(1, 20):.1f}",
              f"omega = {rng.uniform(2, 20):.1f}"]
    if wide and rng.random() < 0.4:
        lines += ["[ground_motion]", 'quantity = "acceleration"', 'type = "sine"',
                  f"amplitude = {rng.uniform(1, 10):.1f}", f"omega = {rng.uniform(2, 20):.1f}"]
    return "\n".join(lines) + "\n"


def verdict(text: str, name: str) -> str:
    """'' where exact holds, else what went wrong."""
    sc = scenario.parse(text, name)
    model, grid = build(sc), time_grid(sc.time)
    tight = Tolerances(rtol=1e-11, atol=1e-14)
    runs = {"exact": solve(model, grid, "exact", Tolerances()), "DOP853": solve(model, grid, "DOP853", tight),
            "Radau": solve(model, grid, "Radau", tight)}
    for method, run in runs.items():
        if not run.success:
            return f"{method} failed: {run.stats.message}"
    exact = with_physics(model, runs["exact"])
    if exact.energy.max_relative_residual > 1e-10:
        return f"exact's balance is off by {exact.energy.max_relative_residual:.2g}"
    peak = float(np.abs(exact.displacement).max())
    apart = lambda a, b: float(np.abs(runs[a].displacement - runs[b].displacement).max()) / peak  # noqa: E731
    if min(apart("exact", "DOP853"), apart("exact", "Radau")) > 1e-6 and apart("DOP853", "Radau") < 1e-6:
        return (f"exact is {apart('exact', 'DOP853'):.2g} of the peak from DOP853 and Radau "
                f"({len(runs['exact'].nonsmooth.events)} against {len(runs['DOP853'].nonsmooth.events)} events)")
    return ""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--trials", type=int, default=25)
    parser.add_argument("--out", default="fuzz")
    parser.add_argument("--wide", action="store_true", help="also breakaway forces, belts and a ground motion")
    args = parser.parse_args()
    rng = random.Random(args.seed)
    out = Path(args.out)
    found = 0
    for trial in range(args.trials):
        text = random_scene(rng, args.wide)
        name = f"fuzz{'_wide' if args.wide else ''}_{args.seed}_{trial}.toml"
        why = verdict(text, name)
        if why:
            found += 1
            out.mkdir(parents=True, exist_ok=True)
            (out / name).write_text(text)
            print(f"{out / name}: {why}")
    print(f"{found} of {args.trials} scenes where exact does not hold")


if __name__ == "__main__":
    main()
