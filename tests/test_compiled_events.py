"""smd's compiled RK23, RK45 and DOP853 on nonsmooth scenes: each mode runs in the compiled kernel
(smdcli.kernels.events), its guards watched and its events located there. The kernel steps as scipy's OdeSolver
of the same pair does (same tableaus, step control and interpolant), so scipy's pair driven from Python, a step at
a time, through the same modes and decisions, is the independent reference: same events, the same history to
the pair's own error, and the energy balance closed to the tolerance."""

import numpy as np
import pytest
from conftest import bundled, model_of

from smdcli.analysis.energy import with_physics
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

RTOL = 1e-8
TOL = Tolerances(rtol=RTOL, atol=RTOL * 1e-3)


def assert_steps_as_scipy(model, grid, method: str) -> None:
    """The compiled pair against scipy's on one scene: events, history, element forces, energy balance."""
    ours = solve(model, grid, method, TOL)
    theirs = solve(model, grid, f"scipy:{method}", TOL)
    assert ours.success and theirs.success
    assert "compiled" in ours.stats.message
    span = float(grid[-1] - grid[0])
    assert [(e, kind) for _, e, kind in ours.nonsmooth.events] == [(e, kind) for _, e, kind in theirs.nonsmooth.events]
    if ours.nonsmooth.events:
        times = np.array([t for t, _, _ in ours.nonsmooth.events]) - np.array([t for t, _, _ in theirs.nonsmooth.events])
        assert np.abs(times).max() <= 100 * RTOL * span
    # the same steps but for rounding, or fewer: the kernel integrates a yielding spring's loss as fy d' in its mode,
    # smooth across the unloading, where scipy's right-hand side takes fy |d'| with its kink there
    assert ours.stats.steps_accepted <= 1.01 * theirs.stats.steps_accepted + 2
    peak = float(np.abs(theirs.displacement).max())
    assert np.abs(ours.displacement - theirs.displacement).max() <= 100 * RTOL * peak
    force = float(np.nanmax(np.abs(theirs.nonsmooth.tension)))
    assert np.nanmax(np.abs(ours.nonsmooth.tension - theirs.nonsmooth.tension)) <= 1e3 * RTOL * force
    for name, values in theirs.nonsmooth.internal.items():
        size = max(float(np.abs(values).max()), 1e-300)
        assert np.abs(ours.nonsmooth.internal[name] - values).max() <= 1e3 * RTOL * size
    # the energy terms integrated in the kernel close the balance as scipy's do: to the tolerance, or to the pair's
    # own global error where that is larger (RK23, an impact's restart)
    ours_residual = with_physics(model, ours).energy.max_relative_residual
    theirs_residual = with_physics(model, theirs).energy.max_relative_residual
    assert ours_residual <= max(10 * RTOL, 1.5 * theirs_residual)


@pytest.mark.parametrize("stem, method", [("coulomb_free_decay", "DOP853"), ("bouncing_ball", "RK45"),
                                          ("stick_slip_belt", "DOP853"), ("vibro_impact_gap", "DOP853"),
                                          ("coulomb_free_decay", "RK23"),
                                          ("bouc_wen_multisine", "DOP853"), ("friction_isolated_building", "RK45")])
def test_the_compiled_pair_steps_a_bundled_nonsmooth_scene_as_scipys_pair_does(stem, method):
    _, model, grid = bundled(stem)
    assert_steps_as_scipy(model, grid, method)


ONE_MASS = """
[time]
end = 6.0
step = 0.01
[[mass]]
name = "m"
m = 1.0
x0 = 0.05
[[spring]]
connects = ["ground", "m"]
k = 100.0
"""


@pytest.mark.parametrize("extra", [
    # Stribeck friction on a belt: the falling slip force the kernel evaluates, stick and slip on a moving surface
    '[[friction]]\nconnects = ["ground", "m"]\nforce = 2.0\nstatic = 3.0\nstribeck_velocity = 0.05\n'
    'viscous = 0.2\nbelt_velocity = 0.1\n',
    # regularized friction: the tanh law, no events
    '[[friction]]\nconnects = ["ground", "m"]\nforce = 1.0\nregularization = 0.01\n',
    # a compliant stop beside a cubic spring: contact stiffness, its damper's loss, separation
    '[[stop]]\nconnects = ["ground", "m"]\nmin = -0.02\nk = 2.0e4\nc = 5.0\n'
    '[[spring]]\nconnects = ["ground", "m"]\nlaw = "cubic"\nk = 10.0\nk3 = 1.0e4\n',
    # a bilinear spring under a sine force: yield and unload, the always-there stiffness b k
    '[[spring]]\nconnects = ["ground", "m"]\nlaw = "bilinear"\nk = 400.0\nfy = 4.0\nhardening = 0.1\n'
    '[[damper]]\nconnects = ["ground", "m"]\nc = 0.3\n'
    '[[force]]\non = "m"\ntype = "sine"\namplitude = 20.0\nomega = 9.0\n',
])
def test_each_law_the_kernel_evaluates_agrees_with_the_python_right_hand_side(extra):
    _, model, grid = model_of(ONE_MASS + extra)
    assert_steps_as_scipy(model, grid, "DOP853")


def test_two_masses_with_friction_between_them_and_a_stop_step_as_scipy_does():
    # a contact between two moving masses (its constraint projected out of both) and a rigid stop's impacts
    text = """
[time]
end = 5.0
step = 0.01
[[mass]]
name = "a"
m = 1.0
v0 = 0.5
[[mass]]
name = "b"
m = 0.5
[[spring]]
connects = ["ground", "a"]
k = 50.0
[[spring]]
connects = ["b", "ground"]
k = 20.0
[[friction]]
connects = ["a", "b"]
force = 0.8
static = 1.0
[[stop]]
connects = ["ground", "a"]
max = 0.06
restitution = 0.7
"""
    _, model, grid = model_of(text)
    assert_steps_as_scipy(model, grid, "RK45")
