"""Every sweep member equals `simulate` of the scene with that member's values written into it, for every damping
form and structural parameter: a cross of the sweep's batched families (matrices interpolated between corner
members) with [damping]. Modal damping is not affine in the stiffness or the mass: a sweep of spring[0].k of a
3-storey frame with modal = 0.05 had the member at the scenario's own stiffness 1.3 % of the peak off (its C off
by 2,561 N s/m) while the file stated 5e-11."""

import numpy as np
import pytest

from smdcli import scenario
from smdcli.api import simulate
from smdcli.model import build, time_grid
from smdcli.sweep import build_family, read_spec, set_parameter, solve_family

FRAME = """
[time]
end = 2.0
step = 0.01
[[mass]]
name = "m1"
m = 1000.0
x0 = 0.01
[[mass]]
name = "m2"
m = 1500.0
[[mass]]
name = "m3"
m = 800.0
[[spring]]
connects = ["ground", "m1"]
k = 1.0e6
[[spring]]
connects = ["m1", "m2"]
k = 1.4e6
[[spring]]
connects = ["m2", "m3"]
k = 0.7e6
[[damper]]
connects = ["m1", "m2"]
c = 300.0
[[force]]
on = "m3"
type = "sine"
amplitude = 500.0
omega = 25.0
"""

DAMPING = {
    "modal": "[damping]\nmodal = 0.05\n",
    "modal_per_mode": "[damping]\nmodal = [0.02, 0.05, 0.1]\n",
    "rayleigh_coefficients": "[damping]\nalpha = 0.4\nbeta = 0.002\n",
    "rayleigh_two_frequencies": "[damping]\nzeta = 0.03\nomega = [20.0, 80.0]\n",
    "none": "",
}
PARAMETERS = [(("spring[0].k",), ("linspace(5e5, 2e6, 4)",)), (("mass.m2.m",), ("900, 1500, 2400",)),
              (("spring[1].k", "mass.m3.m"), ("1e6, 1.4e6, 3e6", "500, 800"))]


@pytest.mark.parametrize("parameters, values", PARAMETERS)
@pytest.mark.parametrize("damping", sorted(DAMPING))
def test_every_member_equals_simulate_of_its_scene(tmp_path, damping, parameters, values):
    import tomllib

    import tomli_w

    text = FRAME + DAMPING[damping]
    sc = scenario.parse(text, "frame.toml")
    family = build_family(sc, read_spec(sc, {"parameter": parameters, "values": values}))
    result = solve_family(family)
    grid = time_grid(sc.time)
    for s in range(len(family)):
        doc = tomllib.loads(text)
        for path, value in zip(parameters, family.values[s]):
            set_parameter(doc, path, float(value))
        member_path = tmp_path / f"member{s}.toml"
        member_path.write_text(tomli_w.dumps(doc))
        reference = simulate(member_path)
        assert np.array_equal(reference.time, grid)
        peak = np.abs(reference.displacement).max()
        # both exact (the matrix exponential): rounding apart, the members' C and K from different sums
        assert np.abs(result.displacement[s] - reference.displacement).max() <= 1e-11 * peak, (damping, s)
        np.testing.assert_allclose(family.model(s).C, build(scenario.load(member_path)).C, rtol=1e-12,
                                   atol=1e-12 * np.abs(family.model(s).C).max())
