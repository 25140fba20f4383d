"""Numbers and words that read right: units that follow an element's law, rigid-body modes named so, a record's
drifted displacement warned of, names a path cannot hold answered with the path that works, --help in plain words."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from conftest import SCENARIOS, one_dof

FREE_FREE = """
[time]
end = 1.0
step = 0.01
[[mass]]
name = "a"
m = 1.3
v0 = 1.0
[[mass]]
name = "b"
m = 1.7
[[mass]]
name = "c"
m = 0.3
[[spring]]
connects = ["a", "b"]
k = 4.1
[[spring]]
connects = ["c", "b"]
k = 7.3
[[damper]]
connects = ["c", "b"]
c = 0.3
"""


def test_a_quadratic_dampers_coefficient_is_in_its_own_units(tmp_path, cli):
    scene = tmp_path / "quadratic.toml"
    scene.write_text(one_dof(c=0.5, law="quadratic", end=1.0, step=0.1))
    assert cli("sweep", scene, "--param", "damper[0].c", "--values", "0.5,1", "-o", tmp_path, "--no-plots",
               "--quiet").exit_code == 0
    with h5py.File(tmp_path / "quadratic_sweep.h5") as f:
        assert f["parameters/damper[0].c"].attrs["units"] == "N s^2/m^2"  # force c |v| v: N over (m/s)^2
        assert f["grid/damper[0].c"].attrs["units"] == "N s^2/m^2"
    linear = tmp_path / "linear.toml"
    linear.write_text(one_dof(c=0.5, end=1.0, step=0.1))
    assert cli("sweep", linear, "--param", "damper[0].c", "--values", "0.5,1", "-o", tmp_path, "--no-plots",
               "--quiet").exit_code == 0
    with h5py.File(tmp_path / "linear_sweep.h5") as f:
        assert f["parameters/damper[0].c"].attrs["units"] == "N s/m"


def test_a_free_free_chain_has_a_rigid_body_mode_named_so(tmp_path, cli):
    scene = tmp_path / "free.toml"
    scene.write_text(FREE_FREE)
    data = json.loads(cli("info", scene, "--json").stdout)
    regimes = [m["regime"] for m in data["modes"]]
    assert regimes[0] == "rigid-body" and "rigid-body" not in regimes[1:]
    # the two elastic modes: |lambda| of the state matrix's complex pairs (wn = sqrt(l1 l2))
    M, C, K = np.diag([1.3, 1.7, 0.3]), np.array(data["C"]), np.array(data["K"])
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    eig = np.linalg.eigvals(A)
    w = np.sort(np.abs(eig[eig.imag > 1e-9]))
    np.testing.assert_allclose([m["natural_frequency_rad_s"] for m in data["modes"][1:]], w, rtol=1e-10)
    text = cli("info", scene).stdout
    assert "rigid-body" in text and "inf" not in text and "overdamped" not in text


def test_a_record_whose_displacement_drifts_is_warned_of_though_its_velocity_ends_near_rest():
    from smdcli.scenario.records import velocity_drift

    t = np.linspace(0.0, 10.0, 1001)
    velocity = np.sin(np.pi * t / 10.0) * 0.2  # ends at rest
    displacement = np.concatenate([[0.0], np.cumsum((velocity[1:] + velocity[:-1]) / 2 * np.diff(t))])
    assert abs(velocity[-1]) < 1e-12
    warning = velocity_drift("record.csv", velocity, displacement)
    assert warning is not None and "displacement" in warning and f"{displacement[-1]:.4g} m" in warning
    assert velocity_drift("record.csv", velocity) is None  # the velocity alone says nothing
    wave = 0.2 * np.sin(2 * np.pi * t)  # a zero-mean motion: neither drifts
    assert velocity_drift("record.csv", wave, 0.2 / (2 * np.pi) * (1 - np.cos(2 * np.pi * t))) is None


@pytest.mark.parametrize("name", ["Floor 1", "2"])
def test_a_mass_name_a_path_cannot_hold_is_answered_with_its_index(tmp_path, cli, name):
    scene = tmp_path / "named.toml"
    scene.write_text(one_dof(c=0.5, end=1.0, step=0.1).replace('name = "m"', f'name = "{name}"').replace(
        '"ground", "m"]', f'"ground", "{name}"]'))
    result = cli("sweep", scene, "--param", f"mass.{name}.m", "--values", "1,2", "-o", tmp_path / "out")
    assert result.exit_code == 2
    assert "mass[0].m" in result.stderr, result.stderr
    assert cli("sweep", scene, "--param", "mass[0].m", "--values", "1,2", "-o", tmp_path / "out", "--no-plots",
               "--quiet").exit_code == 0


@pytest.mark.parametrize("command", ["simulate", "compare-solvers", "sweep", "spectrum", "phase", "info", "diff",
                                     "export", "draw", "animate"])
def test_help_shows_values_in_plain_words(cli, command):
    text = cli(command, "--help").stdout
    assert "<bool>" not in text and "<str>" not in text and "list[" not in text and "{" not in text, text
    assert "Usage: smd " + command in " ".join(text.split())


def test_a_fixed_step_run_states_its_step_not_a_tolerance_it_never_used(tmp_path, cli):
    fixed = cli("simulate", SCENARIOS / "two_dof_forced.toml", "--method", "rk4", "-o", tmp_path, "--no-plots").stdout
    assert "dt = 0.005 s, fixed" in fixed and "rtol=" not in fixed
    adaptive = cli("simulate", SCENARIOS / "two_dof_forced.toml", "--method", "ode45", "-o", tmp_path,
                   "--no-plots").stdout
    assert "rtol=1e-06 atol=1e-09" in adaptive and "dt = " not in adaptive


def test_a_schematic_gives_units_and_says_what_it_cannot_draw():
    from smdcli import scenario
    from smdcli.plots.schematic import layout, schematic_figure

    car = scenario.load(SCENARIOS / "quarter_car_bump.toml")
    assert {e.label.split(" = ")[1].split(" ", 1)[1] for e in layout(car).elements} == {"N/m", "N s/m"}
    texts = [t.get_text() for t in schematic_figure(car).texts]
    assert any("the wall moves: [ground_motion] displacement" in t for t in texts), texts
    quadratic = scenario.load(SCENARIOS / "one_dof_nonlinear_stiff.toml")
    assert any("N s²/m²" in e.label for e in layout(quadratic).elements)


@pytest.mark.parametrize("stem, says", [("vibro_impact_gap", ["stop1, e = 0.5\nmin -0.005 m, max 0.005 m"]),
                                        ("stick_slip_belt", ["friction1\nF = 2 N, static 3 N\nbelt 0.1 m/s"])])
def test_a_schematic_draws_friction_contacts_and_stops(stem, says):
    """The elements that define a nonsmooth scene are drawn and labelled with their law's numbers (the schematic
    used to say 'not drawn: 1 friction contact, 1 stop'), no label run into the wall."""
    from smdcli import scenario
    from smdcli.plots.schematic import WALL_GAP, layout, schematic_figure

    sc = scenario.load(SCENARIOS / f"{stem}.toml")
    plan = layout(sc)
    assert [e.label for e in plan.elements if e.kind in ("friction", "stop")] == says
    fig = schematic_figure(sc)
    texts = [t.get_text() for ax in fig.axes for t in ax.texts] + [t.get_text() for t in fig.texts]
    assert not any("not drawn" in t for t in texts) and all(label in texts for label in says)
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[0]
    wall = ax.transData.transform((-WALL_GAP, 0))[0]
    for text in ax.texts:  # none runs into the wall
        assert text.get_window_extent(renderer).x0 >= wall, text.get_text()


def test_a_mistyped_option_is_matched_by_its_name_not_its_dashes(cli):
    bogus = cli("simulate", SCENARIOS / "one_dof_underdamped.toml", "--bogus")
    assert bogus.exit_code == 2 and "No such option: --bogus" in bogus.stderr and "--out" not in bogus.stderr
    typo = cli("simulate", SCENARIOS / "one_dof_underdamped.toml", "--metod", "x")
    assert typo.exit_code == 2 and "Possible options: --method" in typo.stderr


def test_an_animation_frame_moves_the_wall_with_the_ground():
    from smdcli import scenario
    from smdcli.plots.common import _figure
    from smdcli.plots.schematic import WALL_GAP, SPACING, draw, layout

    plan = layout(scenario.load(SCENARIOS / "quarter_car_bump.toml"))
    walls = []
    for ground in (0.0, 0.05):
        ax = _figure().add_subplot()
        draw(ax, plan, [0.0, 0.0], scale=2.0, labels=False, ground=ground)
        thick = [lines for lines in ax.collections if list(lines.get_linewidths()) == [2.5]]  # the wall's post
        walls.append(thick[0].get_segments()[0][0, 0])
    assert walls[0] == pytest.approx(SPACING + WALL_GAP) and walls[1] - walls[0] == pytest.approx(2.0 * 0.05)


def test_a_two_parameter_overlay_tells_both_parameters_apart(tmp_path, cli, monkeypatch):
    """Many members under a colour map: colour is the first parameter, line style the second (two values)."""
    from matplotlib.figure import Figure

    seen = []
    original = Figure.savefig

    def keep(fig, *args, **kwargs):
        seen.append(fig)
        return original(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    assert cli("sweep", SCENARIOS / "one_dof_underdamped.toml", "--param", "damper[0].c", "--values",
               "linspace(0.5, 4, 8)", "--param", "spring[0].k", "--values", "10,40", "-o", tmp_path,
               "--quiet").exit_code == 0
    overlay = next(f for f in seen if f.axes[0].get_legend() is not None)
    legend = overlay.axes[0].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == ["spring[0].k = 10 N/m", "spring[0].k = 40 N/m"]
    styles = {line.get_linestyle() for line in overlay.axes[0].get_lines() if len(line.get_xdata())}
    assert styles == {"-", "-."}
