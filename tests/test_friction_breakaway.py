"""Friction whose breakaway (static) force is above its kinetic force, the usual case, and a force's jump past a
stuck contact's breakaway: every method against an independent event-driven solution (friction_reference.py,
scipy's solve_ivp with its own event location, not smd's modes or decisions).

Before these were fixed, `exact` stopped at the first breakaway ("events do not settle"): the contact, just let
go with zero speed, read the rounding of a speed that had never moved (-5e-19 m/s) as a reversal; the integrators
slid the block the wrong way (peak 0.53 m where the reference gives 0.045 m) with friction creating energy. A step
force that took a stuck contact past its breakaway left it stuck, holding 10x its static force, in every method.
"""

import numpy as np
import pytest
from conftest import model_of
from friction_reference import FrictionReference

from smdcli.analysis.energy import with_physics
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

TIGHT = Tolerances(rtol=1e-10, atol=1e-13)
METHODS = [("exact", 1e-9), ("DOP853", 1e-6), ("Radau", 1e-6), ("ode45", 1e-6), ("BDF", 1e-6), ("LSODA", 1e-6)]


def sine(amplitude, omega):
    return lambda t: amplitude * np.sin(omega * t)


# name -> (scenario text, reference: (M, C, K, contacts [(row, kinetic, static)], force(t) -> (n,), breaks))
SCENES = {
    "block_on_ground_sine": ("""
[time]
end = 2.0
step = 0.002
[[mass]]
name = "m1"
m = 200.0
[[friction]]
connects = ["ground", "m1"]
force = 150.0
static = 200.0
[[force]]
on = "m1"
type = "sine"
amplitude = 1000.0
frequency = 5.0
""", ([[200.0]], [[0.0]], [[0.0]], [([1.0], 150.0, 200.0)],
      lambda t: np.array([1000.0 * np.sin(2 * np.pi * 5.0 * t)]), ())),
    "spring_damper_sticks_and_slips": ("""
[time]
end = 6.0
step = 0.01
[[mass]]
name = "m1"
m = 1.0
x0 = 0.02
[[spring]]
connects = ["ground", "m1"]
k = 100.0
[[damper]]
connects = ["ground", "m1"]
c = 0.5
[[friction]]
connects = ["ground", "m1"]
force = 2.0
static = 3.0
[[force]]
on = "m1"
type = "sine"
amplitude = 6.0
omega = 4.0
""", ([[1.0]], [[0.5]], [[100.0]], [([1.0], 2.0, 3.0)], lambda t: np.array([6.0 * np.sin(4.0 * t)]), ())),
    "block_on_a_cart": ("""
[time]
end = 5.0
step = 0.01
[[mass]]
name = "cart"
m = 2.0
[[mass]]
name = "block"
m = 1.0
[[spring]]
connects = ["ground", "cart"]
k = 80.0
[[damper]]
connects = ["ground", "cart"]
c = 0.4
[[friction]]
connects = ["cart", "block"]
force = 3.0
static = 4.5
[[force]]
on = "cart"
type = "sine"
amplitude = 30.0
omega = 5.0
""", ([[2.0, 0.0], [0.0, 1.0]], [[0.4, 0.0], [0.0, 0.0]], [[80.0, 0.0], [0.0, 0.0]], [([-1.0, 1.0], 3.0, 4.5)],
      lambda t: np.array([30.0 * np.sin(5.0 * t), 0.0]), ())),
    "step_past_breakaway": ("""
[time]
end = 1.0
step = 0.01
[[mass]]
name = "m1"
m = 10.0
[[spring]]
connects = ["ground", "m1"]
k = 1000.0
[[friction]]
connects = ["ground", "m1"]
force = 150.0
static = 232.0
[[force]]
on = "m1"
type = "step"
amplitude = 2422.0
t0 = 0.1
""", ([[10.0]], [[0.0]], [[1000.0]], [([1.0], 150.0, 232.0)], lambda t: np.array([2422.0 * (t >= 0.1)]), (0.1,))),
    "step_between_two_masses_off_the_grid": ("""
[time]
end = 1.5
step = 0.01
[[mass]]
name = "m1"
m = 3.0
[[mass]]
name = "m2"
m = 2.0
[[spring]]
connects = ["ground", "m1"]
k = 400.0
[[spring]]
connects = ["m1", "m2"]
k = 150.0
[[friction]]
connects = ["m1", "m2"]
force = 20.0
static = 30.0
[[force]]
on = "m2"
type = "step"
amplitude = 90.0
t0 = 0.2345
""", ([[3.0, 0.0], [0.0, 2.0]], [[0.0, 0.0], [0.0, 0.0]], [[550.0, -150.0], [-150.0, 150.0]],
      [([-1.0, 1.0], 20.0, 30.0)], lambda t: np.array([0.0, 90.0 * (t >= 0.2345)]), (0.2345,))),
}


def reference(name: str, grid: np.ndarray, model) -> np.ndarray:
    M, C, K, contacts, force, breaks = SCENES[name][1]
    return FrictionReference(M, C, K, contacts, force, breaks).run(grid, model.x0, model.v0)


@pytest.mark.parametrize("method, tolerance", METHODS)
@pytest.mark.parametrize("name", sorted(SCENES))
def test_breakaway_then_kinetic_slip_matches_an_independent_solution(name, method, tolerance):
    """Every method follows the reference: stuck up to the static force, then slipping against the kinetic one, and
    stuck again where the force that would hold it is within the static; friction never creates energy."""
    sc, model, grid = model_of(SCENES[name][0], f"{name}.toml")
    expected = reference(name, grid, model)
    result = solve(model, grid, method, TIGHT)
    assert result.success, result.message
    peak = float(np.abs(expected).max())
    assert peak > 1e-3  # the scene moves
    np.testing.assert_allclose(result.displacement, expected, rtol=0, atol=tolerance * peak)
    physics = with_physics(model, result)
    friction = physics.energy.friction
    assert np.all(np.diff(friction) >= -1e-12 * max(float(np.abs(friction).max()), 1e-300))
    assert friction[-1] > 0
    assert "slip" in {kind for _, _, kind in result.nonsmooth.events}


def test_the_reference_sees_what_a_wrong_breakaway_does():
    """The reference itself: the block's slip from rest is the closed form while it lasts (x = (F0 / omega (t - sin
    omega t / omega) ... ) checked at its first stick-free stretch), so a solution that slid the wrong way fails."""
    m, fk, fs, F0, w = 200.0, 150.0, 200.0, 1000.0, 2 * np.pi * 5.0
    t_break = np.arcsin(fs / F0) / w
    grid = np.linspace(0.0, 0.05, 501)
    ref = FrictionReference([[m]], [[0.0]], [[0.0]], [([1.0], fk, fs)], lambda t: np.array([F0 * np.sin(w * t)]))
    x = ref.run(grid, np.zeros(1), np.zeros(1))[:, 0]
    slipping = grid > t_break

    def closed(t):  # m x'' = F0 sin(w t) - fk from rest at t_break
        s = t - t_break
        return (F0 / w * (np.cos(w * t_break) * s - (np.sin(w * t) - np.sin(w * t_break)) / w)
                - 0.5 * fk * s ** 2) / m

    np.testing.assert_allclose(x[slipping], closed(grid[slipping]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(x[~slipping], 0.0, rtol=0, atol=1e-15)
