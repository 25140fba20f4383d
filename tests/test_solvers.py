"""Every integrator against the exact solution, auto's choices, and refusals."""

import numpy as np
import pytest
from conftest import bundled, model_of, one_dof

from smdcli.errors import ScenarioError
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances


load = bundled


@pytest.mark.parametrize("method", ["RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA",
                                    "ode45", "ode23", "ode113", "ode15s"])
def test_integrators_meet_their_tolerance_on_the_two_dof_scene(method):
    _, model, grid = load("two_dof_forced")
    exact = solve(model, grid, "exact", Tolerances())
    r = solve(model, grid, method, Tolerances(rtol=1e-8, atol=1e-10))
    assert r.success
    error = np.abs(r.displacement - exact.displacement).max() / np.abs(exact.displacement).max()
    # Global error is a small multiple of the local tolerance on this 5 s, 2-mode scene.
    assert error < 1e-5
    assert r.stats.nfev > 0 and r.stats.steps_accepted > 0
    if method != "LSODA":
        assert r.stats.steps_rejected >= 0


def test_auto_chooses_and_says_why():
    for name, method in [("one_dof_undamped", "closed_form"), ("three_dof_forced", "exact"),
                         ("three_dof_matrix_free", "exact"), ("one_dof_nonlinear_stiff", "taylor")]:
        _, model, grid = load(name)
        if name == "one_dof_nonlinear_stiff":
            grid = grid[grid <= 2.0]
        r = solve(model, grid, "auto", Tolerances())
        assert r.stats.method == method, name
        assert r.stats.requested_method == "auto"
        assert len(r.stats.reason) > 20


def test_nonlinear_scene_auto_agrees_with_tight_radau():
    sc, model, grid = load("one_dof_nonlinear_stiff")
    tol = Tolerances(sc.solver.rtol, sc.solver.atol)
    r = solve(model, grid, "auto", tol)
    ref = solve(model, grid, "Radau", Tolerances(1e-12, 1e-15))
    peak = np.abs(ref.displacement).max()
    assert abs(peak - 0.0029939) < 1e-6
    assert np.abs(r.displacement - ref.displacement).max() / peak < 1e-5


def test_auto_switches_to_implicit_when_the_trajectory_is_stiff():
    """A cubic spring pair with a 1e6:1 stiffness contrast and strong damping is stiff along its run."""
    text = """
[time]
end = 2.0
points = 201
[[mass]]
name = "a"
m = 1.0
x0 = 0.1
[[mass]]
name = "b"
m = 1.0
[[spring]]
connects = ["ground", "a"]
k = 1.0
law = "cubic"
k3 = 1.0
[[spring]]
connects = ["a", "b"]
k = 1e6
[[damper]]
connects = ["a", "b"]
c = 2e4
"""
    _, model, grid = model_of(text)
    r = solve(model, grid, "auto", Tolerances())
    assert r.stats.method == "Radau"
    assert "stiff" in r.stats.reason
    ref = solve(model, grid, "BDF", Tolerances(1e-10, 1e-13))
    assert np.abs(r.displacement - ref.displacement).max() < 1e-6


def test_exact_refuses_nonlinear_and_unknown_methods_get_a_hint():
    _, model, grid = model_of(one_dof(1001.0, k=1000.0, law="quadratic"))
    with pytest.raises(ScenarioError, match="'exact' needs a linear model; damper\\[0\\] is nonlinear"):
        solve(model, grid, "exact", Tolerances())
    with pytest.raises(ScenarioError, match="unknown method 'rk54'.*did you mean"):
        solve(model, grid, "rk54", Tolerances())


def test_quadratic_damper_jacobian_matches_finite_differences():
    _, model, _ = model_of(one_dof(1001.0, k=1000.0, law="quadratic"))
    y = np.array([0.01, -0.3])
    J = model.jacobian(0.0, y)
    eps = 1e-7
    fd = np.column_stack([(model.rhs(0.0, y + eps * e, np.empty(0)) - model.rhs(0.0, y - eps * e, np.empty(0))) / (2 * eps)
                          for e in np.eye(2)])
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-6)


def test_divergence_is_a_failure_with_the_time_reached():
    """A softening cubic spring started beyond its barrier escapes to infinity in finite time."""
    text = """
[time]
end = 10.0
step = 0.01
[[mass]]
name = "m"
m = 1.0
x0 = 2.0
[[spring]]
connects = ["ground", "m"]
k = 1.0
law = "cubic"
k3 = -1.0
"""
    _, model, grid = model_of(text)
    r = solve(model, grid, "RK45", Tolerances())
    assert not r.success
    assert 0.1 < r.t_failed < 10.0
    assert "failed at t =" in r.stats.message
    assert np.isnan(r.displacement[-1, 0])


STEP_AS_EXPRESSION = one_dof(0.4, end=5.0, step=0.05, extra="""
[[force]]
on = "m"
type = "expression"
expr = "sin(3*t)*exp(-0.1*t) + heaviside(t - 1.013)"
""")
STEP_AS_STEP = one_dof(0.4, end=5.0, step=0.05, extra="""
[[force]]
on = "m"
type = "expression"
expr = "sin(3*t)*exp(-0.1*t)"
[[force]]
on = "m"
type = "step"
amplitude = 1.0
t0 = 1.013
""")


@pytest.mark.parametrize("method", ["rk4", "newmark", "DOP853", "Radau", "ode45", "LSODA"])
def test_a_jump_inside_an_expression_is_restarted_at_as_a_step_force_is(method):
    """heaviside(t - 1.013) in an expression is the step force at 1.013: every method restarts there (the edge
    is located to adjacent floats) and takes the left limit before it, so both scenes give one answer to
    rounding, the compiled kernels included. Before, fixed-step RK4 stepped across it with 36x the error."""
    tol = Tolerances(rtol=1e-9, atol=1e-12)
    _, expression_model, grid = model_of(STEP_AS_EXPRESSION)
    _, step_model, _ = model_of(STEP_AS_STEP)
    assert expression_model.breakpoints(0.0, 5.0).tolist() == pytest.approx([1.013], abs=1e-15)
    expression_run = solve(expression_model, grid, method, tol)
    step_run = solve(step_model, grid, method, tol)
    peak = np.abs(step_run.displacement).max()
    assert np.abs(expression_run.displacement - step_run.displacement).max() <= 1e-12 * peak


@pytest.mark.parametrize("method", ["auto", "taylor", "exact", "RK45"])
def test_the_applied_force_is_worked_out_where_first_read_and_is_the_models(method):
    """Result.force may be held as the function that computes it (a Taylor run, read for its motion alone, never
    needs the (N, n) array): read, it is model.applied_force on the grid; Result.changed keeps it unread,
    dataclasses.replace and pickling read it, and the arrays are equal whichever way they were made."""
    import dataclasses
    import pickle

    from conftest import SCENARIOS, model_of

    text = (SCENARIOS / "three_dof_forced.toml").read_text()
    if method in ("auto", "taylor"):  # nonlinear: auto's Taylor series
        text += '[[spring]]\nconnects = ["ground", "m1"]\nlaw = "cubic"\nk = 0.0\nk3 = 100.0\n'
    _, model, grid = model_of(text)
    result = solve(model, grid, method, Tolerances())
    assert result.success and result.stats.method == ("taylor" if method == "auto" else method)
    expected = model.applied_force(grid)
    assert np.abs(expected).max() > 0
    deferred = callable(result.__dict__["force"])
    # where the solver gives the acceleration, not derived from the force: Taylor's, exact's dense exponential's
    assert deferred == (result.stats.method in ("taylor", "exact"))
    changed = result.changed(notes=("a note",))
    assert callable(changed.__dict__["force"]) == deferred and changed.notes == ("a note",)
    np.testing.assert_array_equal(changed.force, expected)
    assert not callable(changed.__dict__["force"]) and changed.force is changed.force  # kept once worked out
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(result)).force, expected)
    np.testing.assert_array_equal(dataclasses.replace(result, notes=()).force, expected)
    with pytest.raises(TypeError, match="no field nonsense"):
        result.changed(nonsense=1)
