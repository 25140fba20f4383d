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


SQUARE_WAVE = """
[time]
end = 3.0
step = 0.01
[[mass]]
name = "m0"
m = 1.0
[[spring]]
connects = ["ground", "m0"]
k = 50.0
[[force]]
on = "m0"
type = "square"
amplitude = 1.0
period = PERIOD
"""


@pytest.mark.parametrize("period", [0.77, 0.8, 0.3])
def test_a_force_s_edges_between_samples_leave_the_shared_force_s_steps_right(period):
    """The batched recurrence makes its members' force terms 64 steps at a time; a step holding a force's edge
    (0.77 s's half-periods fall between samples: the one at 1.925 s opens the fourth block) is split and taken on its
    own, and the block it opened was left unmade: the rest of the run used the block before's forcing, 90 % of the
    peak off while the file stated 4e-13 (the differential tests found it). Every member to rounding."""
    text = SQUARE_WAVE.replace("PERIOD", repr(period))
    sc = scenario.parse(text, "square.toml")
    family = build_family(sc, read_spec(sc, {"parameter": ("spring[0].k",), "values": ("35.0, 70.0",)}))
    result = solve_family(family)
    for s, k in enumerate((35.0, 70.0)):
        reference = simulate(scenario.parse(text.replace("k = 50.0", f"k = {k!r}"), "member.toml"))
        peak = np.abs(reference.displacement).max()
        assert np.abs(result.displacement[s] - reference.displacement).max() <= 1e-11 * peak, (period, s)
        assert float(result.stated_accuracy[s]) <= 1e-11


NONSMOOTH = """
[time]
end = 2.0
step = 0.01
[[mass]]
name = "m1"
m = 100.0
[[mass]]
name = "m2"
m = 60.0
[[spring]]
connects = ["ground", "m1"]
LAW
[[spring]]
connects = ["m1", "m2"]
k = 2.0e4
[[damper]]
connects = ["m1", "m2"]
c = 40.0
[[friction]]
connects = ["ground", "m1"]
force = 30.0
[[stop]]
connects = ["m1", "m2"]
min = -0.02
restitution = 0.5
[[force]]
on = "m2"
type = "sine"
amplitude = 400.0
omega = 9.0
"""
LAWS = {"bilinear": 'law = "bilinear"\nk = 5.0e4\nfy = 150.0\nhardening = 0.1',
        "elastoplastic": 'law = "elastoplastic"\nk = 5.0e4\nfy = 150.0',
        "bouc_wen": 'law = "bouc_wen"\nk = 5.0e4\nalpha = 0.1\nbeta = 150.0\ngamma = 150.0\nn = 1.0'}
NONSMOOTH_PARAMETERS = ["spring[0].k", "spring[0].yield", "spring[1].k", "mass.m2.m", "damper[0].c",
                        "friction[0].force", "stop[0].min"]


@pytest.mark.parametrize("parameter", NONSMOOTH_PARAMETERS)
@pytest.mark.parametrize("law", sorted(LAWS))
def test_every_member_of_a_nonsmooth_scene_equals_simulate_of_its_scene(tmp_path, law, parameter):
    """A hysteretic spring's k lives in its law, not in K: a sweep that interpolated K alone left each member's
    law at the base's k (a bilinear storey 300 times softer peaked at 0.0084 m where simulate gives 0.10 m).
    Every member, whatever field is swept, is simulate of its own scene, to the stated accuracy of both runs."""
    import tomllib

    import tomli_w

    text = NONSMOOTH.replace("LAW", LAWS[law])
    if parameter == "spring[0].yield":  # the law's own yield field
        parameter = "spring[0].beta" if law == "bouc_wen" else "spring[0].fy"
    sc = scenario.parse(text, "scene.toml")
    base_value = {"spring[0].k": 5e4, "spring[0].fy": 150.0, "spring[0].beta": 150.0, "spring[1].k": 2e4, "mass.m2.m": 60.0,
                  "damper[0].c": 40.0, "friction[0].force": 30.0, "stop[0].min": -0.02}[parameter]
    values = f"{0.5 * base_value}, {2.0 * base_value}"
    family = build_family(sc, read_spec(sc, {"parameter": (parameter,), "values": (values,)}))
    result = solve_family(family)
    for s in range(len(family)):
        assert result.success[s], result.messages[s]
        doc = tomllib.loads(text)
        set_parameter(doc, parameter, float(family.values[s][0]))
        member_path = tmp_path / f"member{s}.toml"
        member_path.write_text(tomli_w.dumps(doc))
        reference = simulate(member_path)
        peak = np.abs(reference.displacement).max()
        allowed = 10 * (reference.stats.stated_accuracy + float(result.stated_accuracy[s])) * peak
        assert np.abs(result.displacement[s] - reference.displacement).max() <= allowed, (law, parameter, s)


def test_members_of_a_long_chain_are_solved_one_by_one_and_equal_simulate(tmp_path, cli):
    """Above BATCHED_DOFS the batched recurrence's Python loop over (2n)^2 entries a step costs more than each member's
    own exact solve (at 2,500 masses it did not finish in 10 minutes): 40 masses go one by one, each equal to
    `simulate` of its scene; the terminal lists the first DOFs and the largest peak, not 40 of them a member."""
    from test_large import chain

    from smdcli.sweep import members

    assert 40 > members.BATCHED_DOFS
    text = chain(40, end=1.0, step=0.01)
    path = tmp_path / "chain.toml"
    path.write_text(text)
    sc = scenario.load(path)
    family = build_family(sc, read_spec(sc, {"parameter": ("spring[0].k",), "values": ("90, 110",)}))
    result = solve_family(family)
    assert "threads" in result.how or "process" in result.how, result.how
    for s, k in enumerate((90.0, 110.0)):
        member = tmp_path / f"k{s}.toml"
        member.write_text(text.replace("k = 100.0", f"k = {k}", 1))
        reference = simulate(member)
        peak = np.abs(reference.displacement).max()
        assert np.abs(result.displacement[s] - reference.displacement).max() <= 1e-11 * peak
    shown = cli("sweep", path, "--param", "spring[0].k", "--values", "90,110", "--no-plots", "-o", tmp_path / "out")
    assert shown.exit_code == 0, shown.output
    assert "m5 = " in shown.stdout and "m6 = " not in shown.stdout and "(40 DOFs; the largest," in shown.stdout
