"""Make bouc_wen_benchmark_test.csv: the Bouc-Wen benchmark's published model (../bouc_wen_benchmark_fit.toml at
the true values) run by DOP853 at rtol 1e-12 under the first second of its multisine, the mass's displacement in mm
with Gaussian noise of 1 % of its RMS (seeded), at the scenario's 1 kHz.

    python scenarios/measured/make_bouc_wen_test.py
"""

from pathlib import Path

import numpy as np

import smdcli
from smdcli.sweep.family import scenario_with

HERE = Path(__file__).resolve().parent
TRUE = {"spring[0].k": 1.0e5, "spring[0].alpha": 0.5, "spring[0].beta": 800.0, "spring[0].gamma": -1100.0,
        "damper[0].c": 10.0}
NOISE = 0.01  # of the channel's RMS

scene = scenario_with(smdcli.load(HERE.parent / "bouc_wen_benchmark_fit.toml"), TRUE)
run = smdcli.simulate(scene, method="DOP853", rtol=1e-12, atol=1e-16)
x = run.displacement[:, 0] * 1e3
rng = np.random.default_rng(20261130)
noisy = x + NOISE * np.sqrt(np.mean(x**2)) * rng.standard_normal(len(x))
with open(HERE / "bouc_wen_benchmark_test.csv", "w") as f:
    f.write("time,m.displacement [mm]\n")
    for t, value in zip(run.time[1:], noisy[1:]):  # from the first sample after the start, as a logger would begin
        f.write(f"{t:.3f},{value:.9e}\n")
