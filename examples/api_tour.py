"""A tour of smd's Python API: load a scenario, simulate it, read what came back, write it, export it.

Run from the repository root or anywhere: python examples/api_tour.py
"""

from pathlib import Path
import tempfile

import numpy as np

import smdcli

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"

# A scenario from a file (validated: bad input raises ScenarioError naming the file and field)
scenario = smdcli.load(SCENARIOS / "two_dof_forced.toml")
print(scenario.title, "-", len(scenario.masses), "masses")

# Simulate: nothing is written. The scenario's own method (auto: exact for a linear scene) unless you say
result = smdcli.simulate(scenario)
print(f"{result.stats.method}: {len(result.time)} samples of {', '.join(result.dofs)}")
print("peak |x| per DOF [m]:", np.abs(result.displacement).max(axis=0))

# The run's own physical accuracy check: the energy balance closes to rounding for the exact solver
energy = result.energy
print(f"energy residual {energy.max_relative_residual:.1e}; dissipated {energy.dissipated[-1]:.4g} J, "
      f"input {energy.input[-1]:.4g} J")

# Element forces, tension positive, and the ground's reaction
for name, force in zip(result.elements.spring_names, result.elements.spring.T):
    print(f"{name}: peak |T| = {np.abs(force).max():.4g} N")
print(f"peak reaction {np.abs(result.elements.reaction).max():.4g} N")

# Another method, tighter: its error against the exact run, and its energy check beside it
dop = smdcli.simulate(scenario, method="DOP853", rtol=1e-8, atol=1e-11)
error = np.abs(dop.displacement - result.displacement).max() / np.abs(result.displacement).max()
print(f"DOP853 rtol 1e-8: error {error:.1e}, energy residual {dop.energy.max_relative_residual:.1e}")

# Plain data for a DataFrame: pandas.DataFrame(result.to_dict()["displacement"], index=result.time)
data = result.to_dict()
print("to_dict keys:", ", ".join(data))

# The same HDF5 file `smd simulate` writes
with tempfile.TemporaryDirectory() as folder:
    path = smdcli.write(result, Path(folder) / "two_dof_forced.h5")
    print("wrote", path.name, f"({path.stat().st_size // 1024} kB)")
