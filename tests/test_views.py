"""smd phase, smd draw and smd animate: what they draw is checked against independent solutions."""

import math

import h5py
import numpy as np
import pytest
from conftest import SCENARIOS

from smdcli import scenario
from smdcli.plots.schematic import layout


def curves(path):
    with h5py.File(path) as f:
        return [(f[f"curves/{k}"].attrs["label"], f[f"curves/{k}/time"][()], f[f"curves/{k}/displacement"][()],
                 f[f"curves/{k}/velocity"][()]) for k in sorted(f["curves"])]


def test_phase_of_the_regimes_family_is_figure_9_3(cli, tmp_path):
    from test_sweep import book_smdsyssim

    result = cli("phase", SCENARIOS / "one_dof_regimes_sweep.toml", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    drawn = curves(tmp_path / "one_dof_regimes_sweep_portrait.h5")
    assert [c[0] for c in drawn] == ["No damping: zeta = 0", "Underdamped: 0 < zeta < 1", "Overdamped: zeta > 1",
                                     "Critically damped: zeta = 1"]
    for (label, t, x, v), D in zip(drawn, (0.0, 2.0, 13.0, 10.0)):
        assert np.abs(x - book_smdsyssim(1.0, D, 25.0, 0.1, 0.0, t)).max() < 1e-12
        h = 1e-6
        velocity = (book_smdsyssim(1.0, D, 25.0, 0.1, 0.0, t + h) - book_smdsyssim(1.0, D, 25.0, 0.1, 0.0, t - h)) / (2 * h)
        assert np.abs(v - velocity).max() < 1e-7
    assert (tmp_path / "one_dof_regimes_sweep_portrait.png").stat().st_size > 20_000


def test_poincare_points_converge_to_the_exact_steady_state(cli, tmp_path):
    """one_dof_harmonic: F = 10 cos(5 t) on m = 2.5, c = 2.5, k = 25; once per period the state tends to
    the steady state x = |H| F0 cos(-theta), v = -|H| F0 w sin(-theta)."""
    result = cli("phase", SCENARIOS / "one_dof_harmonic.toml", "--poincare", "--periods", "60", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    sc = scenario.load(SCENARIOS / "one_dof_harmonic.toml")
    force = sc.forces[0]
    m, c, k = sc.masses[0].m, sc.dampers[0].coef, sc.springs[0].coef
    w = force.omega
    H = 1 / (k - w**2 * m + 1j * w * c)
    theta = -np.angle(H)
    with h5py.File(tmp_path / "one_dof_harmonic_portrait.h5") as f:
        x, v = f["poincare/000/displacement"][()], f["poincare/000/velocity"][()]
        period = f["poincare"].attrs["period_s"]
    assert period == pytest.approx(2 * math.pi / w)
    assert len(x) == 61
    assert sc.forces[0].type == "cosine"
    assert x[-1] == pytest.approx(abs(H) * force.amplitude * math.cos(force.phase - theta), abs=1e-9)
    assert v[-1] == pytest.approx(-abs(H) * force.amplitude * w * math.sin(force.phase - theta), abs=1e-8)
    gaps = np.hypot(np.diff(x), np.diff(v))
    assert gaps[-1] < 1e-6 * gaps[0]


def test_phase_overlays_scenarios_and_initial_conditions(cli, tmp_path):
    result = cli("phase", SCENARIOS / "three_dof_forced.toml", SCENARIOS / "three_dof_free.toml", "--dof", "m1,m3",
                 "-o", tmp_path)
    assert result.exit_code == 0, result.output
    assert len(curves(tmp_path / "three_dof_forced_and_1_more_portrait.h5")) == 4
    result = cli("phase", SCENARIOS / "one_dof_underdamped.toml", "--ic", "x0=0.1,v0=0", "--ic", "x0=0,v0=1",
                 "-o", tmp_path)
    assert result.exit_code == 0, result.output
    drawn = curves(tmp_path / "one_dof_underdamped_portrait.h5")
    assert [(c[2][0], c[3][0]) for c in drawn] == [(0.1, 0.0), (0.0, 1.0)]


@pytest.mark.parametrize("args, message", [
    (["one_dof_underdamped.toml", "--poincare"], "no periodic force"),
    (["one_dof_underdamped.toml", "--dof", "m9"], "has no DOF 'm9'"),
    (["one_dof_underdamped.toml", "two_dof_forced.toml", "--ic", "x0=1"], "one scenario"),
])
def test_bad_phase_input_is_exit_2(cli, tmp_path, args, message):
    result = cli("phase", *[SCENARIOS / a if a.endswith(".toml") else a for a in args], "-o", tmp_path / "out")
    assert result.exit_code == 2, result.output
    assert message in result.stderr and not (tmp_path / "out").exists()


def test_schematic_elements_from_element_and_matrix_forms():
    chain = layout(scenario.load(SCENARIOS / "three_dof_free.toml"))
    matrix = layout(scenario.load(SCENARIOS / "three_dof_matrix_free.toml"))
    assert chain.left_wall and chain.right_wall and matrix.left_wall and matrix.right_wall
    springs = sorted((str(e.a), str(e.b)) for e in matrix.elements if e.kind == "spring")
    assert springs == [("0", "1"), ("1", "2"), ("2", "right"), ("left", "0")]
    labels = {(str(e.a), str(e.b)): e.label for e in matrix.elements if e.kind == "spring"}
    # The book's K of three_MASS.m: k1 = 25, k2 = 5, k3 = k4 = 30, so m3 to the wall is k3 + k4 - k3 = 30 + 30.
    assert labels[("left", "0")] == "k = 25 N/m" and labels[("0", "1")] == "k = 5 N/m"
    assert labels[("1", "2")] == "k = 30 N/m"
    nonlinear = layout(scenario.load(SCENARIOS / "duffing_frequency_response.toml"))
    assert [e.nonlinear for e in nonlinear.elements] == [True, False]


def test_draw_writes_a_schematic(cli, tmp_path):
    for name in ("three_dof_forced", "two_dof_forced", "one_dof_nonlinear_stiff", "three_dof_matrix_forced"):
        result = cli("draw", SCENARIOS / f"{name}.toml", "-o", tmp_path)
        assert result.exit_code == 0, result.output
        assert (tmp_path / f"{name}_schematic.png").stat().st_size > 10_000


def test_animate_a_twenty_second_gif_under_5_mb(cli, tmp_path):
    from PIL import Image

    result = cli("animate", SCENARIOS / "three_dof_free.toml", "--end", "20", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    gif = tmp_path / "three_dof_free.gif"
    assert gif.stat().st_size < 5 * 2**20
    with Image.open(gif) as im:
        assert im.n_frames == 400 and im.info["duration"] == 50
        first = np.asarray(im.convert("L"))
        im.seek(200)
        middle = np.asarray(im.convert("L"))
    assert (first != middle).mean() > 0.001  # the masses moved


def test_bad_animate_input_is_exit_2(cli, tmp_path):
    result = cli("animate", SCENARIOS / "three_dof_free.toml", "--end", "999", "-o", tmp_path / "out")
    assert result.exit_code == 2 and "--start/--end" in result.stderr
    assert not (tmp_path / "out").exists()


def test_phase_of_scenes_with_different_dofs_and_its_own_name(cli, tmp_path):
    """Without --dof each scenario draws its own DOFs (the issue: 'has no DOF m1' when --dof was never given);
    phase writes <name>_portrait.*, never simulate's <stem>_phase.png, and --name sets the name."""
    a, b = SCENARIOS / "one_dof_underdamped.toml", SCENARIOS / "three_dof_free.toml"
    result = cli("phase", a, b, "-o", tmp_path)
    assert result.exit_code == 0, result.output
    assert len(curves(tmp_path / "one_dof_underdamped_and_1_more_portrait.h5")) == 4  # m, then m1..m3
    result = cli("phase", a, "--name", "mine", "-o", tmp_path)
    assert result.exit_code == 0 and (tmp_path / "mine_portrait.png").exists()
    simulate = cli("simulate", a, "-o", tmp_path)
    assert simulate.exit_code == 0 and (tmp_path / "one_dof_underdamped_phase.png").exists()
    bad = cli("phase", a, "--name", "../escape", "-o", tmp_path)
    assert bad.exit_code == 2 and "--name" in bad.stderr
