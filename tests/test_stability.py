"""Where methods fail, measured: stability limits of the fixed-step methods, stiffness, breakpoints."""

import math

import numpy as np
import pytest
from conftest import SCENARIOS, model_of, one_dof

from smdcli import scenario
from smdcli.commands.compare import compare, parse_steps
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

# Undamped three-mass chain, masses 1, 2, 1.5, started on the first mass so every mode moves.
UNDAMPED_3DOF = """
[time]
end = 20.0
step = 0.01
[[mass]]
name = "m1"
m = 1.0
x0 = 0.1
[[mass]]
name = "m2"
m = 2.0
[[mass]]
name = "m3"
m = 1.5
v0 = 0.2
[[spring]]
connects = ["ground", "m1"]
k = 400.0
[[spring]]
connects = ["m1", "m2"]
k = 300.0
[[spring]]
connects = ["m2", "m3"]
k = 250.0
"""


@pytest.fixture(scope="module")
def chain():
    _, model, grid = model_of(UNDAMPED_3DOF)
    w = model.modes.natural_frequencies
    # omega_max from the generalized eigenproblem K phi = w^2 M phi, computed independently here.
    w_check = np.sqrt(np.linalg.eigvals(np.linalg.solve(model.M, model.K)).real.max())
    assert w.max() == pytest.approx(w_check, rel=1e-12)
    return model, grid, float(w.max())


def energy(model, r):
    """Kinetic plus potential energy at every output time."""
    x, v = r.displacement, r.velocity
    return 0.5 * np.einsum("ti,ij,tj->t", v, model.M, v) + 0.5 * np.einsum("ti,ij,tj->t", x, model.K, x)


@pytest.mark.parametrize("method, limit", [("central_difference", 2.0), ("rk4", 2 * math.sqrt(2))])
def test_explicit_method_is_bounded_below_its_limit_and_diverges_above(chain, method, limit):
    model, grid, w_max = chain
    stable = solve(model, grid, method, Tolerances(dt=0.95 * limit / w_max))
    assert stable.success
    assert np.abs(stable.displacement).max() < 2 * np.abs(solve(model, grid, "exact", Tolerances()).displacement).max()
    unstable = solve(model, grid, method, Tolerances(dt=1.05 * limit / w_max))
    assert not unstable.success
    assert "grew past" in unstable.stats.message and unstable.t_failed < grid[-1]


def test_explicit_euler_energy_grows_at_any_step_by_exactly_1_plus_h2w2(chain):
    """On an undamped 1-DOF scene Euler multiplies w^2 x^2 + v^2 by exactly 1 + (h w)^2 per step."""
    _, model, grid = model_of(one_dof(0.0, k=25.0, end=2.0, step=0.01))
    for hw in (0.001, 0.01, 0.1):
        h = hw / 5.0
        r = solve(model, grid, "euler", Tolerances(dt=h))
        e = 25.0 * r.displacement[:, 0] ** 2 + r.velocity[:, 0] ** 2
        steps = round(2.0 / h)
        assert e[-1] / e[0] == pytest.approx((1 + hw**2) ** steps, rel=1e-9)
        assert e[-1] > e[0]
    model3, grid3, w_max = chain
    r = solve(model3, grid3, "euler", Tolerances(dt=0.01 / w_max))
    assert energy(model3, r)[-1] > 1.05 * energy(model3, r)[0]


def test_newmark_average_acceleration_conserves_energy_at_100x_the_explicit_limit(chain):
    model, grid, w_max = chain
    r = solve(model, grid, "newmark", Tolerances(dt=100 * 2.0 / w_max))
    assert r.success
    # Output is interpolated between steps; the steps themselves land on t = 0 and the end.
    e = energy(model, r)
    assert e[-1] == pytest.approx(e[0], rel=1e-10)  # to rounding over 280 steps


def test_linear_acceleration_newmark_has_its_limit_of_sqrt_12(chain):
    model, grid, w_max = chain
    ok = solve(model, grid, "newmark", Tolerances(dt=0.95 * math.sqrt(12) / w_max,
                                                  options=(("scheme", "linear_acceleration"),)))
    bad = solve(model, grid, "newmark", Tolerances(dt=1.05 * math.sqrt(12) / w_max,
                                                   options=(("scheme", "linear_acceleration"),)))
    assert ok.success and not bad.success


def modal_energies(model, r):
    """Energy in each mode at every output time (undamped, M-orthonormal shapes)."""
    from scipy.linalg import eigh

    w2, phi = eigh(model.K, model.M)
    q, qd = r.displacement @ model.M @ phi, r.velocity @ model.M @ phi
    return 0.5 * (qd**2 + w2 * q**2)


@pytest.mark.parametrize("method, options", [("hht", (("alpha", -0.1),)), ("generalized_alpha", (("rho_inf", 0.5),))])
def test_dissipative_methods_damp_the_high_mode_and_not_the_low_one(method, options):
    """Two masses with modes at about 0.7 and 1400 rad/s; h * w is 0.007 for the low and 14 for the high."""
    text = """
[time]
end = 10.0
step = 0.01
[[mass]]
name = "a"
m = 1.0
x0 = 0.1
[[mass]]
name = "b"
m = 1.0
x0 = 0.1001
[[spring]]
connects = ["ground", "a"]
k = 1.0
[[spring]]
connects = ["a", "b"]
k = 1e6
"""
    _, model, grid = model_of(text)
    r = solve(model, grid, method, Tolerances(dt=0.01, options=options))
    e = modal_energies(model, r)
    assert e[-1, 1] < 1e-6 * e[0, 1]  # high mode gone
    assert e[-1, 0] == pytest.approx(e[0, 0], rel=1e-3)  # low mode kept
    plain = solve(model, grid, "newmark", Tolerances(dt=0.01))
    assert modal_energies(model, plain)[-1, 1] == pytest.approx(e[0, 1], rel=1e-9)  # Newmark keeps both


def steps_to_reach(model, grid, method, target, reference):
    """Accepted steps of the loosest rtol on a ladder whose error is below target: the method's own, as
    compare-solvers charts it (balance=False: no rerun measuring a low-order method's error)."""
    peak = np.abs(reference.displacement).max()
    for rtol in (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
        r = solve(model, grid, method, Tolerances(rtol, rtol * 1e-3, balance=False))
        if r.success and np.abs(r.displacement - reference.displacement).max() / peak < target:
            return r.stats.steps_accepted
    raise AssertionError(f"{method} never reached {target}")


@pytest.mark.parametrize("name", ["one_dof_linear_stiff", "two_mass_stiff_chain"])
def test_on_stiff_scenes_rk45_needs_ten_times_the_steps_of_implicit_methods(name):
    sc = scenario.load(SCENARIOS / f"{name}.toml")
    model, grid = build(sc), time_grid(sc.time)
    assert model.is_stiff and model.stiffness_ratio > 999
    exact = solve(model, grid, "exact", Tolerances())
    target = 1e-4
    rk45 = steps_to_reach(model, grid, "RK45", target, exact)
    for method in ("ode15s", "Radau", "ode23s"):
        assert rk45 > 10 * steps_to_reach(model, grid, method, target, exact), method
    forced = solve(model, grid, "RK45", Tolerances())
    assert any("stiff" in note for note in forced.notes)  # the user who forces an explicit method is told
    assert "stiff (stiffness ratio" in solve(model, grid, "auto", Tolerances()).stats.reason


def test_linear_stiff_scene_matches_its_closed_form():
    sc = scenario.load(SCENARIOS / "one_dof_linear_stiff.toml")
    model, grid = build(sc), time_grid(sc.time)
    r = solve(model, grid, "auto", Tolerances())
    u = (np.exp(-grid) - np.exp(-1000 * grid)) / 999
    np.testing.assert_allclose(r.displacement[:, 0], u, rtol=0, atol=1e-14)
    assert np.sort(model.modes.eigenvalues.real) == pytest.approx([-1000.0, -1.0])


def test_square_wave_loses_accuracy_without_breakpoints():
    sc = scenario.load(SCENARIOS / "one_dof_square_wave.toml")
    model, grid = build(sc), time_grid(sc.time)
    exact = solve(model, grid, "exact", Tolerances())
    peak = np.abs(exact.displacement).max()
    errors = {}
    for breakpoints in (True, False):
        r = solve(model, grid, "RK45", Tolerances(1e-6, 1e-9, breakpoints=breakpoints))
        errors[breakpoints] = np.abs(r.displacement - exact.displacement).max() / peak
    assert errors[True] < 1e-4
    assert errors[False] > 10 * errors[True]


def test_compare_records_failures_without_hiding_the_runs_that_worked(chain):
    model, grid, w_max = chain
    sc = scenario.parse(UNDAMPED_3DOF, "chain.toml")
    steps = parse_steps("", w_max, 20.0)
    c = compare(sc, model, grid, ["central_difference", "ode45"], [(1e-4, 1e-7)], steps, repeats=1)
    cd = {round(r.h_omega, 6): r for r in c.runs if r.method == "central_difference"}
    assert not cd[2.1].success and not cd[3.0].success
    assert cd[1.9].success and cd[0.02].error < cd[0.2].error / 50  # second order: 100x for 10x
    ode45 = [r for r in c.runs if r.method == "ode45"]
    assert len(ode45) == 1 and ode45[0].success
    exact = solve(model, grid, "exact", Tolerances()).displacement
    direct = solve(model, grid, "ode45", Tolerances(1e-4, 1e-7)).displacement
    assert ode45[0].error == pytest.approx(np.abs(direct - exact).max() / np.abs(exact).max(), rel=1e-12)
    assert c.reference_method.startswith("exact")


def _crosses(fig) -> list[int]:
    """How many runs each panel of a chart crosses out (its 'x' markers with data)."""
    return [sum(len(line.get_xdata()) for line in ax.get_lines() if line.get_marker() == "x")
            for ax in fig.axes]


def test_diverged_runs_are_failures_in_the_table_json_file_and_every_chart(tmp_path, cli):
    """two_dof_forced (omega_max 8.3 rad/s): central difference past h w = 2 and explicit Euler at large steps
    blow up; each such run is a failure, with its reason, in every place compare-solvers reports it."""
    import json

    import h5py

    from smdcli.plots.compare import energy_precision_figure, stability_figure, work_precision_figure

    ran = cli("compare-solvers", SCENARIOS / "two_dof_forced.toml", "--methods", "central_difference,euler,newmark",
              "--repeats", "1", "-o", tmp_path, "--json")
    assert ran.exit_code == 0, ran.output
    runs = json.loads(ran.stdout)["runs"]
    by = {(r["method"], round(r["h_omega"], 6)): r for r in runs}
    for h in (2.1, 2.6, 3.0):  # past central difference's limit of 2: grows without bound
        r = by[("central_difference", h)]
        assert not r["success"] and r["message"].startswith(("diverged", "failed")), r
    assert by[("central_difference", 1.9)]["success"]
    assert not by[("euler", 3.0)]["success"] and "diverged" in by[("euler", 3.0)]["message"]
    assert all(r["success"] for r in runs if r["method"] == "newmark")  # unconditionally stable: never crossed out
    failed = [r for r in runs if not r["success"]]
    with h5py.File(tmp_path / "two_dof_forced_compare.h5") as f:
        assert list(f["runs/success"][()]) == [r["success"] for r in runs]
        assert [m.decode() for m in f["runs/message"][()]] == [r["message"] for r in runs]
    table = cli("compare-solvers", SCENARIOS / "two_dof_forced.toml", "--methods", "central_difference,euler,newmark",
                "--repeats", "1", "-o", tmp_path, "--no-plots").stdout
    assert table.count("FAILED: diverged") + table.count("FAILED: failed") >= 3 + 1
    assert sum("FAILED" in line for line in table.splitlines()) == len(failed)

    sc = scenario.load(SCENARIOS / "two_dof_forced.toml")
    model, grid = build(sc), time_grid(sc.time)
    steps = parse_steps("", model.omega_max, float(grid[-1] - grid[0]))
    c = compare(sc, model, grid, ["central_difference", "euler", "newmark"], [], steps, repeats=1)
    bad = [r for r in c.runs if not r.success]
    assert {(r.method, round(r.h_omega, 6)) for r in bad} == {(r["method"], round(r["h_omega"], 6)) for r in failed}
    assert _crosses(work_precision_figure(c, "t")) == [len(bad), len(bad)]
    assert _crosses(energy_precision_figure(c, "t"))[0] == len(bad)
    assert _crosses(stability_figure(c, "t", {}))[0] == len(bad)
