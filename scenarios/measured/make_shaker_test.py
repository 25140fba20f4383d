"""Make three_storey_shaker_test.csv: the true frame of ../three_storey_shaker.toml run exactly, its three floors'
absolute accelerations in g with Gaussian noise of 2 % of each channel's RMS (seeded), at the scenario's 200 Hz.

    python scenarios/measured/make_shaker_test.py
"""

from pathlib import Path

import numpy as np

import smdcli
from smdcli.sweep.family import scenario_with

HERE = Path(__file__).resolve().parent
TRUE = {"spring[0].k": 3.0e6, "spring[1].k": 2.4e6, "spring[2].k": 1.6e6, "damping.alpha": 0.4,
        "damping.beta": 0.002}
NOISE = 0.02  # of each channel's RMS
G = 9.80665

scene = scenario_with(smdcli.load(HERE.parent / "three_storey_shaker.toml"), TRUE)
run = smdcli.simulate(scene, method="exact")
rng = np.random.default_rng(20261129)
columns = ["time"]
values = [run.time]
for j, dof in enumerate(run.dofs):
    a = run.acceleration[:, j] / G
    values.append(a + NOISE * np.sqrt(np.mean(a**2)) * rng.standard_normal(len(a)))
    columns.append(f"{dof}.acceleration [g]")
rows = np.column_stack(values)[1:]  # from the first sample after the start, as a logger would begin
with open(HERE / "three_storey_shaker_test.csv", "w") as f:
    f.write(",".join(columns) + "\n")
    for row in rows:
        f.write(f"{row[0]:.3f}," + ",".join(f"{v:.9e}" for v in row[1:]) + "\n")
