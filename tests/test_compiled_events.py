"""smd's compiled ODE methods on nonsmooth scenes (RK23, RK45, DOP853, Radau, BDF and ode15s, ode23s, ode23t,
ode23tb): each mode runs in a compiled kernel (smdcli.kernels.events, radau, bdf, stiff), its guards watched and
its events located there (smdcli.kernels.guards). The kernels step
as scipy's OdeSolver of the same method does (same tableaus, step control and interpolant), so scipy's method
driven from Python, a step at a time, through the same modes and decisions, is the independent reference: same
events, the same history to the method's own error, and the energy balance closed as well. (An implicit method's
Jacobian of a mode is a forward difference in the kernel and scipy's num_jac (or smd's own difference) in Python:
the Newton iterations differ, the steps agree to 1 %.)"""

import numpy as np
import pytest
from conftest import bundled, model_of

from smdcli.analysis.energy import with_physics
from smdcli.elements.base import NEWMARK_CORE
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

RTOL = 1e-8
TOL = Tolerances(rtol=RTOL, atol=RTOL * 1e-3, balance=False)  # each method as it steps: no rerun


REFERENCE = {"ode15s": "scipy:BDF"}  # the scipy-driven class of each compiled method (else scipy:METHOD)


def assert_steps_as_scipy(model, grid, method: str) -> None:
    """The compiled method against scipy's on one scene: events, history, element forces, energy balance."""
    ours = solve(model, grid, method, TOL)
    theirs = solve(model, grid, REFERENCE.get(method, f"scipy:{method}"), TOL)
    assert ours.success and theirs.success
    assert "compiled" in ours.stats.message
    span = float(grid[-1] - grid[0])
    assert [(e, kind) for _, e, kind in ours.nonsmooth.events] == [(e, kind) for _, e, kind in theirs.nonsmooth.events]
    if ours.nonsmooth.events:
        times = np.array([t for t, _, _ in ours.nonsmooth.events]) - np.array([t for t, _, _ in theirs.nonsmooth.events])
        assert np.abs(times).max() <= 100 * RTOL * span
    # the same steps but for rounding, or fewer: the kernel integrates a yielding spring's loss as fy d' in its mode,
    # smooth across the unloading, where scipy's right-hand side takes fy |d'| with its kink there
    assert ours.stats.steps_accepted <= 1.01 * theirs.stats.steps_accepted + 4
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
                                          ("bouc_wen_multisine", "DOP853"), ("friction_isolated_building", "RK45"),
                                          ("bouc_wen_multisine", "Radau"), ("stick_slip_belt", "Radau"),
                                          ("vibro_impact_gap", "Radau"), ("vibro_impact_gap", "ode15s"),
                                          ("stick_slip_belt", "ode23s"), ("coulomb_free_decay", "ode23t"),
                                          ("bouncing_ball", "ode23tb")])
def test_the_compiled_pair_steps_a_bundled_nonsmooth_scene_as_scipys_pair_does(stem, method):
    """Over the scene's first BUNDLED_SPAN seconds: scipy's pair, stepped from Python, took 10-17 s a scene over the
    whole run, a fifth of CI's budget; the first seconds hold several of each scene's events."""
    _, model, grid = bundled(stem)
    grid = grid[grid <= grid[0] + BUNDLED_SPAN]
    assert_steps_as_scipy(model, grid, method)
    if stem != "bouc_wen_multisine":  # the one smooth law: no events
        assert len(solve(model, grid, method, TOL).nonsmooth.events) >= 3


BUNDLED_SPAN = 4.0


ONE_MASS = """
[time]
end = 3.0
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
    for method in ("DOP853", "Radau", "ode15s"):
        assert_steps_as_scipy(model, grid, method)


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


# ------------------------------------------------------------------------ the Newmark family's return mapping


def test_the_compiled_return_mapping_is_the_laws_own():
    # the kernel's state updates against the laws (smdcli.elements): the elastic-plastic return map is the law's
    # own; Bouc-Wen's trapezoidal step solves z - z0 = h/2 (z'(z0) + z'(z)) of the law's z', its tangent is that
    # root's derivative in the new deformation
    from scipy.optimize import brentq

    from smdcli.elements.bouc_wen import BoucWen
    from smdcli.elements.elastoplastic import Bilinear
    from smdcli.kernels import return_mapping as kernel

    rng = np.random.default_rng(7)
    bw = BoucWen(k=100.0, alpha=0.1, beta=5.0, gamma=5.0, n=1.5, A=1.0)
    p = np.array([(1 - bw.alpha) * bw.k, bw.A, bw.beta, bw.gamma, bw.n])
    bilinear = Bilinear(k=400.0, fy=4.0, hardening=0.1)
    q = np.array([bilinear.core.k, bilinear.core.fy, 0.0, 0.0, 0.0])

    def trapezoid(z0, d0, d1, h):
        rate = (d1 - d0) / h
        return brentq(lambda z: z - z0 - 0.5 * h * (bw.z_rate(z0, rate) + bw.z_rate(z, rate)), -1.0, 1.0, xtol=1e-15,
                      rtol=1e-15)

    for _ in range(200):
        z0, d0, d1, h = rng.normal(0, 0.1), rng.normal(0, 0.2), rng.normal(0, 0.2), rng.uniform(1e-4, 1e-2)
        z, tangent = kernel.z_step(p, z0, d0, d1, h)
        assert z == pytest.approx(trapezoid(z0, d0, d1, h), rel=1e-12, abs=1e-14)
        step = 1e-6 * max(abs(d1), 1e-3)
        slope = (trapezoid(z0, d0, d1 + step, h) - trapezoid(z0, d0, d1 - step, h)) / (2 * step)
        assert tangent == pytest.approx(slope, rel=1e-5, abs=1e-8)
        dp = rng.normal(0, 0.01)
        T, stiffness, dp_new = kernel.spring(NEWMARK_CORE, q, dp, d0, d1, h)
        assert (T, stiffness, dp_new) == pytest.approx(bilinear.return_map(d1, dp), rel=1e-14, abs=1e-16)


JUMPING = ONE_MASS.replace("x0 = 0.05\n", "") + """
[[spring]]
connects = ["ground", "m"]
law = "bilinear"
k = 400.0
fy = 4.0
hardening = 0.1
[[damper]]
connects = ["ground", "m"]
c = 0.5
[ground_motion]
quantity = "displacement"
type = "pulse"
amplitude = 0.05
t0 = 0.5
duration = 0.4
"""


def test_a_spring_yields_through_a_ground_jump_alike_in_every_solver():
    # the ground's displacement pulse jumps the spring's deformation by 5 times its yield deformation: it yields on
    # the way (fy |change of d_p| dissipated), in the exact solver, the ODE family and the Newmark family alike
    _, model, grid = model_of(JUMPING)
    exact = solve(model, grid, "exact", Tolerances())
    physics = with_physics(model, exact).energy
    assert physics.max_relative_residual <= 1e-10
    hysteretic = exact.nonsmooth.energy["hysteretic"]
    assert hysteretic[-1] > 4.0 * 0.04  # at least the first jump's plastic flow: fy (0.05 - 0.01) at b = 0
    dop = solve(model, grid, "DOP853", Tolerances(rtol=1e-10, atol=1e-13))
    # a grid point at a jump holds its left limit in one solver, its right in the other
    away = np.abs(grid[:, None] - np.array([[0.5, 0.9]])).min(axis=1) > 1e-9
    assert np.abs(dop.displacement - exact.displacement)[away].max() <= 1e-8
    # Newmark (average acceleration) converges at second order to the exact history, through both jumps
    errors = [np.abs(solve(model, grid, "newmark", Tolerances(dt=dt)).displacement - exact.displacement).max()
              for dt in (1e-3, 5e-4)]
    assert errors[0] <= 2e-5 and 3.0 <= errors[0] / errors[1] <= 5.0
    fine = solve(model, grid, "newmark", Tolerances(dt=2.5e-4))
    assert abs(fine.nonsmooth.energy["hysteretic"][-1] - hysteretic[-1]) <= 1e-5 * hysteretic[-1]


def test_a_smooth_law_without_a_kernel_code_is_refused_by_the_compiled_methods_and_auto_steps_it_with_scipy(
        monkeypatch, cli, tmp_path):
    """A law whose tension is not linear between events and that names no kernel code (Law.kernel_piece's default)
    would lose its force in a compiled integrator: the compiled methods refuse it in one line naming the element and
    scipy's counterpart, and auto takes scipy's pair, which agrees with the compiled run of the law as it is. A second
    of the sine's hysteresis: scipy's Radau at rtol 1e-9 in Python took 25 s of CI over 3 s."""
    from smdcli.elements.base import Law
    from smdcli.elements.bouc_wen import BoucWen

    text = ONE_MASS.replace("end = 3.0", "end = 1.0") + ('[[spring]]\nconnects = ["ground", "m"]\nlaw = "bouc_wen"\nk = 100.0\nalpha = 0.1\nbeta = 5.0\n'
                       'gamma = 5.0\nn = 1.5\nA = 1.0\n[[force]]\non = "m"\ntype = "sine"\namplitude = 20.0\n'
                       'omega = 9.0\n')
    _, model, grid = model_of(text)
    compiled = solve(model, grid, "Radau", Tolerances(rtol=1e-9, atol=1e-12))
    monkeypatch.setattr(BoucWen, "kernel_piece", Law.kernel_piece)
    path = tmp_path / "bw.toml"
    path.write_text(text)
    refused = cli("simulate", str(path), "--method", "DOP853", "--no-plots", "-o", str(tmp_path / "out"))
    assert refused.exit_code == 2 and not (tmp_path / "out").exists()
    assert "spring[1]'s law bouc_wen has no compiled kernel" in refused.stderr, refused.stderr
    assert "'scipy:DOP853'" in refused.stderr and len(refused.stderr.strip().splitlines()) == 1
    _, model, grid = model_of(text)
    auto = solve(model, grid, "auto", Tolerances(rtol=1e-9, atol=1e-12))
    assert auto.stats.method == "scipy:Radau" and "no compiled kernel" in auto.stats.reason
    peak = np.abs(compiled.displacement).max()
    assert np.abs(auto.displacement - compiled.displacement).max() < 1e-6 * peak


FLAT_AT_ITS_KINK = """[time]
end = 1.0
step = 0.01
[[mass]]
name = "m0"
m = 0.657
[[mass]]
name = "m1"
m = 2.92
[[mass]]
name = "m2"
m = 2.01
x0 = 0.01
[[spring]]
connects = ["ground", "m0"]
law = "bouc_wen"
k = 91.3
alpha = 0.1
beta = 20.0
gamma = 20.0
n = 1.0
[[spring]]
connects = ["m0", "m1"]
k = 400.0
[[spring]]
connects = ["m1", "m2"]
k = 179.0
[[damper]]
connects = ["m1", "m2"]
c = 0.665
[[force]]
on = "m2"
type = "sine"
amplitude = 2.55
omega = 5.0
"""


@pytest.mark.parametrize("method", ["DOP853", "scipy:DOP853", "RK45", "Radau", "BDF"])
def test_a_kink_whose_quantity_is_flat_where_it_is_taken_is_taken_once(method):
    """The Bouc-Wen spring's mass at rest until m2's pull reaches it through two springs: its speed grows as t^3, flat
    at its kink (v = 0) from the start, where the interpolant's rounding dips below zero and above at random. Each
    such dip was taken for the kink again, 4.5e-16 s on: DOP853 (compiled and scipy's) stepped 6,653 times at rtol
    1e-9 and at 1e-10 failed after 2,000,000 steps saying the scene may be stiff. Now a kink's dip must be deeper
    than that rounding: every method runs in the steps of the smooth motion (77 to 1,670 at rtol 1e-10), and agrees
    with Radau at rtol 1e-12 within 1,000 times its rtol (measured 7e-12 to 3.8e-9 of the peak, BDF the largest)."""
    _, model, grid = model_of(FLAT_AT_ITS_KINK)
    reference = solve(model, grid, "Radau", Tolerances(rtol=1e-12, atol=1e-15, balance=False))
    found = solve(model, grid, method, Tolerances(rtol=1e-10, atol=1e-13, balance=False))
    assert found.success, found.stats.message
    assert found.stats.steps_accepted < 5000, found.stats.steps_accepted
    peak = np.abs(reference.displacement).max()
    assert np.abs(found.displacement - reference.displacement).max() <= 1e-7 * peak
