"""The commands as a user runs them: outputs, HDF5 layout, exit codes, startup cost."""

import importlib.metadata
import json
import subprocess
import sys

import h5py
import numpy as np
import pytest
from conftest import SCENARIOS, bundled, model_of, one_dof

ALL = sorted(SCENARIOS.glob("*.toml"))
BOOK = ["one_dof_nonlinear_stiff", "one_dof_undamped", "one_dof_underdamped", "one_dof_overdamped",
        "one_dof_critical", "one_dof_square_fourier", "one_dof_square_wave", "one_dof_harmonic",
        "two_dof_forced", "three_dof_forced", "three_dof_free", "three_dof_matrix_forced", "three_dof_matrix_free",
        "three_dof_matrix_files"]  # the last: the book's matrices read from Matrix Market files
STUDIES = ["one_dof_linear_stiff", "two_mass_stiff_chain"]  # stiff scenes for compare-solvers
SWEEPS = ["one_dof_regimes_sweep", "ic_underdamped", "ic_critical", "ic_overdamped", "frequency_response_zeta",
          "two_dof_frequency_response", "duffing_frequency_response"]  # scenes with a [sweep] table
GROUND = ["shear_frame_record", "quarter_car_bump", "transmissibility_1dof", "shock_half_sine"]  # support motion
ANALYSES = ["five_storey_building", "component_random_vibration",  # response-spectrum analysis (smd rsa)
            "three_storey_shaker",  # identification from a shaker test (smd fit)
            "bouc_wen_benchmark_fit",  # the Bouc-Wen benchmark's model identified from its multisine (smd fit)
            "tmd_one_dof", "five_storey_tmd",  # tuned mass dampers to tune (smd optimize)
            "ida_frame"]  # a frame of yielding storeys for incremental dynamic analysis (smd ida)
NONSMOOTH = ["elastoplastic_record", "shear_frame_bilinear", "bouc_wen_multisine", "bouc_wen_benchmark",
             "coulomb_free_decay", "stick_slip_belt", "bouncing_ball", "vibro_impact_gap", "friction_isolated_building"]  # yield, friction, stops


def test_every_book_scenario_is_bundled():
    assert sorted(p.stem for p in ALL) == sorted(BOOK + STUDIES + SWEEPS + GROUND + NONSMOOTH + ANALYSES)


@pytest.mark.slow
def test_every_scenario_runs_in_one_batch(tmp_path, cli):
    result = cli("simulate", *ALL, "-o", tmp_path, "--no-plots", "--json")
    assert result.exit_code == 0, result.output
    summaries = json.loads(result.stdout)
    assert [s["scenario"] for s in summaries] == [str(p) for p in ALL]
    for s, path in zip(summaries, ALL):
        assert s["success"]
        assert (tmp_path / f"{path.stem}.h5").exists()
        assert not list(tmp_path.glob("*.part"))


def test_simulate_writes_the_documented_layout_and_plots(tmp_path, cli):
    result = cli("simulate", SCENARIOS / "two_dof_forced.toml", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    assert "method   exact" in result.stdout and "peak |x|" in result.stdout
    for name in ("two_dof_forced_response.png", "two_dof_forced_phase.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with h5py.File(tmp_path / "two_dof_forced.h5") as f:
        assert f.attrs["kind"] == "simulate" and f.attrs["schema_version"] == 1
        assert "[[mass]]" in f.attrs["scenario"]
        N = len(f["time"])
        assert N == 1001 and f["time"].attrs["units"] == "s"
        assert [d.decode() for d in f["dof"][()]] == ["m1", "m2"]
        for name, units in (("displacement", "m"), ("velocity", "m/s"), ("acceleration", "m/s^2"), ("force", "N")):
            ds = f[name]
            assert ds.shape == (N, 2) and ds.attrs["units"] == units
            assert ds.dims[0][0].name == "/time" and ds.dims[1][0].name == "/dof"
        solver = f["solver"].attrs
        assert solver["method"] == "exact" and solver["requested_method"] == "auto" and solver["success"]
        for key in ("reason", "rtol", "atol", "dt", "nfev", "njev", "nlu", "steps_accepted", "steps_rejected",
                    "wall_time_s", "message"):
            assert key in solver
        np.testing.assert_array_equal(f["model/K"][()], [[90, -90], [-90, 175]])
        assert f["model/modes"].attrs["natural_frequencies_rad_s"].shape == (2,)
        np.testing.assert_allclose(f["displacement"][0], [1.0, -1.0])
        np.testing.assert_allclose(f["force"][:, 0], 3.3 * np.sin(10 * f["time"][()]), atol=1e-12)
        # The acceleration satisfies the equation of motion on the grid.
        x, v, a = f["displacement"][()], f["velocity"][()], f["acceleration"][()]
        M, C, K = (f[f"model/{m}"][()] for m in "MCK")
        np.testing.assert_allclose(a @ M.T + v @ C.T + x @ K.T, f["force"][()], atol=1e-10)


def test_method_override_and_worst_exit_code(tmp_path, cli):
    bad = tmp_path / "bad.toml"
    bad.write_text("[time]\nend = -1\n")
    result = cli("simulate", SCENARIOS / "one_dof_critical.toml", bad, SCENARIOS / "one_dof_undamped.toml",
                 "-o", tmp_path, "--method", "RK45", "--rtol", "1e-8", "--no-plots")
    assert result.exit_code == 2
    assert (tmp_path / "one_dof_critical.h5").exists() and (tmp_path / "one_dof_undamped.h5").exists()
    with h5py.File(tmp_path / "one_dof_undamped.h5") as f:
        assert f["solver"].attrs["method"] == "RK45" and f["solver"].attrs["rtol"] == 1e-8
    result = cli("simulate", bad, SCENARIOS / "one_dof_undamped.toml", "-o", tmp_path / "ff", "--fail-fast")
    assert result.exit_code == 2 and not (tmp_path / "ff" / "one_dof_undamped.h5").exists()


def test_solver_failure_exits_1_with_where_and_why(tmp_path, cli):
    scenario = tmp_path / "escape.toml"
    scenario.write_text('[time]\nend = 10.0\n[[mass]]\nname = "m"\nm = 1.0\nx0 = 2.0\n'
                        '[[spring]]\nconnects = ["ground", "m"]\nk = 1.0\nlaw = "cubic"\nk3 = -1.0\n')
    result = cli("simulate", scenario, "-o", tmp_path)
    assert result.exit_code == 1
    assert "failed at t =" in result.stderr and "try" in result.stderr
    assert not (tmp_path / "escape.h5").exists()


def test_info_reports_modes_regimes_and_auto(cli):
    result = cli("info", SCENARIOS / "one_dof_critical.toml", "--json")
    data = json.loads(result.stdout)
    assert data["modes"][0]["regime"] == "critically damped"
    assert data["modes"][0]["natural_frequency_rad_s"] == pytest.approx(5.0, rel=1e-15)
    assert data["auto"]["method"] == "closed_form"
    data = json.loads(cli("info", SCENARIOS / "three_dof_matrix_forced.toml", "--json").stdout)
    w = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(np.diag([2.5, 2, 3]), data["K"])).real))
    np.testing.assert_allclose([m["natural_frequency_rad_s"] for m in data["modes"]], w, rtol=0.05)
    data = json.loads(cli("info", SCENARIOS / "one_dof_nonlinear_stiff.toml", "--json").stdout)
    assert data["nonlinear_elements"] == ["damper[0]"]
    assert data["linearized_at_start"]["stiffness_ratio"] > 1000
    text = cli("info", SCENARIOS / "three_dof_forced.toml").stdout
    assert "stiffness ratio" in text and "auto     exact" in text


def test_a_large_model_is_summarized_on_the_terminal(cli, tmp_path):
    """100 masses: `smd info` and `smd simulate` list a few DOFs, modes and peaks and say where the rest are;
    --json keeps every one."""
    lines = ["[time]", "end = 1.0", "step = 0.01"]
    for i in range(100):
        lines += ["[[mass]]", f'name = "m{i}"', "m = 1.0", "[[spring]]",
                  f'connects = ["{"ground" if i == 0 else f"m{i - 1}"}", "m{i}"]', "k = 100.0"]
    lines += ["[[damper]]", 'connects = ["m99", "ground"]', "c = 5.0", "[[force]]", 'on = "m0"', 'type = "sine"',
              "amplitude = 10.0", "omega = 5.0"]
    path = tmp_path / "chain.toml"
    path.write_text("\n".join(lines) + "\n")
    text = cli("info", path).stdout
    assert "more modes (--json lists them all)" in text and "100 x 100, 100 nonzero (diagonal" in text
    assert "m50" not in text and "m0, m1" in text and "m98, m99" in text
    result = cli("simulate", path, "-o", tmp_path, "--no-plots")
    assert result.exit_code == 0, result.output
    peak = next(line for line in result.stdout.splitlines() if "peak |x|" in line)
    assert "(100 DOFs; the largest" in peak and "m50 " not in peak
    data = json.loads(cli("simulate", path, "-o", tmp_path, "--no-plots", "--json").stdout)
    assert len(data[0]["peak_displacement_m"]) == 100
    with h5py.File(tmp_path / "chain.h5") as f:
        sampled = np.abs(f["displacement"][:]).max(axis=0)
    located = np.array(list(data[0]["peak_displacement_m"].values()))
    # located between samples (solvers.peaks): never below the samples, above them by the curvature's share
    assert np.all(located >= sampled) and np.all(located <= sampled * (1 + 1e-3))


def test_help_does_not_import_heavy_modules():
    code = ("import sys, runpy; sys.argv = ['smd', '--help']\n"
            "try:\n    runpy.run_module('smdcli', run_name='__main__')\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('scipy', 'matplotlib', 'h5py') if m in sys.modules]\n"
            "print('HEAVY', heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "HEAVY []" in out


def test_help_texts_survive_rich_markup():
    """A bracket in an option's help ([[expect]], damper[0]) must not be eaten as a rich style tag."""
    import typer.main
    from rich.text import Text

    from smdcli.cli import app

    group = typer.main.get_command(app)
    for name, command in group.commands.items():
        for param in [command, *command.params]:
            text = getattr(param, "help", None) or ""
            assert Text.from_markup(text).plain == text.replace("\\[", "["), (name, param.name, text)


def test_compare_solvers_writes_table_json_hdf5_and_charts(cli, tmp_path):
    import h5py

    from smdcli.solvers import solve
    from smdcli.solvers.base import Tolerances

    scene = tmp_path / "scene.toml"
    scene.write_text(one_dof(0.4, end=10.0, step=0.01))
    out = tmp_path / "out"
    r = cli("compare-solvers", scene, "--methods", "ode45,ode23s,central_difference",
            "--tolerances", "1e-3/1e-6,1e-5", "--steps", "0.5,0.01", "--repeats", "2", "-o", out, "--json")
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    runs = {(run["method"], run["rtol"] if run["adaptive"] else run["dt"]): run for run in data["runs"]}
    assert len(runs) == 6 and data["reference"].startswith("exact")
    assert runs[("central_difference", 0.5)]["success"] is False  # h * omega = 2.5 > 2
    assert runs[("central_difference", 0.5)]["error"] is None
    _, model, grid = model_of(one_dof(0.4, end=10.0, step=0.01))
    exact = solve(model, grid, "exact", Tolerances()).displacement
    ode23s = solve(model, grid, "ode23s", Tolerances(1e-3, 1e-6)).displacement
    assert runs[("ode23s", 1e-3)]["error"] == pytest.approx(np.abs(ode23s - exact).max() / np.abs(exact).max())
    assert runs[("ode45", 1e-5)]["atol"] == pytest.approx(1e-8)
    # each run's own energy check is of the size of its true error
    assert 0.1 < runs[("ode23s", 1e-3)]["energy_residual"] / runs[("ode23s", 1e-3)]["error"] < 10
    names = sorted(p.name for p in out.iterdir())
    assert names == ["scene_compare.h5", "scene_energy_precision.png", "scene_stability.png", "scene_work_precision.png"]
    with h5py.File(out / "scene_compare.h5") as f:
        assert f.attrs["kind"] == "compare"
        assert list(f["runs/method"].asstr()[:]) == [run["method"] for run in data["runs"]]
        assert f["runs/error"].attrs["units"] == "1" and f["reference/displacement"].shape == (1001, 1)
        assert f["reference"].attrs["stated_accuracy"] == pytest.approx(data["exact"]["stated_accuracy"])
    # The exact solution is a point of its own: its time and the accuracy it states (rounding level here).
    assert 0 < data["exact"]["wall_time_s"] < 1 and 0 < data["exact"]["stated_accuracy"] < 1e-10


def test_compare_solvers_gives_compiled_methods_the_steps_tight_tolerances_need(tmp_path):
    """ode23s at rtol 1e-6 on the book's forced three-DOF chain takes ~500,000 steps: past the 200,000 that a
    Python-driven method is allowed, well inside a compiled method's budget; the chart's table says so."""
    from smdcli.commands.compare import STEP_BUDGET, compare, format_table

    sc, model, grid = bundled("three_dof_forced")
    c = compare(sc, model, grid, ["ode23s"], [(1e-6, 1e-9)], [], repeats=1)
    run = c.runs[0]
    assert run.success and run.steps_accepted > STEP_BUDGET
    assert run.error < 1e-5  # second order, local error control at rtol 1e-6: measured 4.8e-6
    assert "the reference; error column: its stated accuracy" in format_table(c)


def test_compare_solvers_bad_method_is_exit_2_and_writes_nothing(cli, tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(one_dof(0.4))
    r = cli("compare-solvers", scene, "--methods", "ode45,rk54", "-o", tmp_path / "out")
    assert r.exit_code == 2
    assert "--methods: unknown method 'rk54'" in r.stderr and "Traceback" not in r.output
    assert not (tmp_path / "out").exists()
    r = cli("compare-solvers", scene, "--tolerances", "1e-3/x", "-o", tmp_path / "out")
    assert r.exit_code == 2 and "--tolerances" in r.stderr


def test_the_silent_cases_are_loud(cli, tmp_path):
    """A [sweep] table given to simulate is named in the summary; --rtol 0 is refused in one line; a typo is
    named before the field it leaves missing; usage errors are one line."""
    result = cli("simulate", SCENARIOS / "ic_critical.toml", "-o", tmp_path, "--no-plots")
    assert result.exit_code == 0 and "[sweep] table was not run" in result.stdout
    assert "smd sweep" in result.stdout
    for option in ("--rtol", "--atol"):
        result = cli("simulate", SCENARIOS / "one_dof_underdamped.toml", option, "0", "-o", tmp_path)
        assert result.exit_code == 2 and result.stderr.count("\n") == 1 and "positive" in result.stderr
    scene = tmp_path / "typo.toml"
    scene.write_text((SCENARIOS / "one_dof_underdamped.toml").read_text().replace("k = 25.0", "stifness = 25.0"))
    result = cli("simulate", scene, "-o", tmp_path)
    assert result.exit_code == 2 and "stifness: unknown key (did you mean 'k'?)" in result.stderr
    for args in (["simulate"], ["simulate", "x.toml", "--bogus"], ["bogus"], ["sweep", scene, "--method", "ode99"]):
        result = cli(*args)
        assert result.exit_code == 2 and result.stderr.count("\n") == 1, (args, result.stderr)
        assert "╭" not in result.stderr and result.stderr.startswith("smd: ")


def test_an_option_that_is_not_a_number_is_one_line_naming_it(cli, tmp_path):
    """smd coerces its plain options itself (cli_support.plain_coercion, not typer's pydantic adapters): a word
    for a number, an integer or a flag's value is one line with exit 2 and nothing written; a range typer
    checks (sweep --workers, at least 1) still is; good values arrive as their types."""
    out = tmp_path / "out"
    cases = [(["simulate", SCENARIOS / "one_dof_underdamped.toml", "--rtol", "abc"], "'--rtol': 'abc' is not a number"),
             (["compare-solvers", SCENARIOS / "one_dof_underdamped.toml", "--repeats", "2.5"],
              "'--repeats': '2.5' is not an integer"),
             (["sweep", SCENARIOS / "ic_critical.toml", "--workers", "0"], "--workers")]
    for args, words in cases:
        result = cli(*args, "-o", out)
        assert result.exit_code == 2 and result.stderr.count("\n") == 1 and words in result.stderr, result.stderr
        assert not out.exists()
    result = cli("simulate", SCENARIOS / "one_dof_underdamped.toml", "--rtol", "1e-7", "-o", out, "--no-plots",
                 "--json")
    assert result.exit_code == 0
    with h5py.File(out / "one_dof_underdamped.h5") as f:
        assert f.attrs["scipy_version"] == importlib.metadata.version("scipy")


def test_messages_use_the_scenario_words(cli, tmp_path):
    """Force types as the scenario names them, units after values, correct plurals."""
    info = cli("info", SCENARIOS / "one_dof_square_fourier.toml")
    assert "fourier_square" in info.stdout and "fouriersquare" not in info.stdout
    info = cli("info", SCENARIOS / "three_dof_forced.toml")
    assert ": sine" in info.stdout and "harmonic" not in info.stdout
    run = cli("simulate", SCENARIOS / "one_dof_underdamped.toml", "-o", tmp_path, "--no-plots", "--json")
    sweep = cli("sweep", SCENARIOS / "one_dof_regimes_sweep.toml", "--metric", "settling_time", "-o", tmp_path,
                "--no-plots")
    assert "m = 3.5 s" in sweep.stdout and "m = not settled" in sweep.stdout
    expression = tmp_path / "expression.toml"
    expression.write_text((SCENARIOS / "one_dof_underdamped.toml").read_text()
                          + '\n[[force]]\non = "m"\ntype = "expression"\nexpr = "sin(t)"\n')
    result = cli("simulate", expression, "-o", tmp_path, "--no-plots")
    assert "force[0] (expression) has no exact integral" in result.stdout and "table" not in result.stdout
    assert run.exit_code == 0
