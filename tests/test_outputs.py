"""What a run gives beyond the trajectories: element forces, the energy balance, CSV, the Python API, the
state-space export and [[expect]] checks (issue 16), each against an independent reference."""

from __future__ import annotations

import math
import tomllib
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from conftest import ROOT, SCENARIOS, bundled, model_of, one_dof
from smdcli.solvers.run import solve_scenario
from smdcli.analysis.energy import with_physics

LINEAR = sorted(p.stem for p in SCENARIOS.glob("*.toml") if bundled(p.stem)[1].is_linear)


def run(name_or_text, method=None, **kwargs):
    """(model, result with physics) of a bundled scenario by stem, or of scenario text."""
    sc, model, grid = bundled(name_or_text) if "\n" not in name_or_text else model_of(name_or_text)
    return model, with_physics(model, solve_scenario(sc, model, grid, method, **kwargs))


# ------------------------------------------------------------------------------------------------ energy
@pytest.mark.parametrize("stem", LINEAR)
def test_energy_balance_closes_to_rounding_on_every_bundled_linear_scene(stem):
    _, result = run(stem)
    assert result.stats.method in ("exact", "closed_form")
    assert result.energy.max_relative_residual < 1e-10, result.energy.quadrature


def test_energy_balance_of_the_nonlinear_stiff_scene_is_at_its_tolerance():
    _, result = run("one_dof_nonlinear_stiff")
    assert "dense output" in result.energy.quadrature
    assert result.energy.max_relative_residual < 1e-6
    # the quadratic damper took nearly all of the initial kinetic energy 1/2 m v0^2 = 0.5 J
    assert result.energy.dissipated[-1] == pytest.approx(0.5 - result.energy.kinetic[-1] - result.energy.strain[-1],
                                                         rel=1e-6)


def test_dissipated_energy_matches_the_integral_of_the_closed_form_velocity():
    """1-DOF underdamped free response: int c v^2 dt of the analytic v(t), by scipy's adaptive quadrature."""
    from scipy.integrate import quad

    m, k, c, x0 = 1.0, 25.0, 0.8, 0.1
    _, result = run(one_dof(c, k, m, x0))
    wn = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd = wn * math.sqrt(1 - zeta**2)

    def v(t):
        return -x0 * wn / math.sqrt(1 - zeta**2) * math.exp(-zeta * wn * t) * math.sin(wd * t)

    for t_end in (0.5, 2.0, 5.0):
        k_end = int(round(t_end / 0.05))
        reference = quad(lambda t: c * v(t) ** 2, 0.0, t_end, epsabs=1e-16, epsrel=1e-13, limit=200)[0]
        assert result.energy.dissipated[k_end] == pytest.approx(reference, rel=1e-11)


def test_input_work_of_a_harmonic_force_matches_quadrature_of_the_exact_solution():
    """Work of F = F0 sin(w t) on the exact particular + homogeneous response, from the closed form."""
    from scipy.integrate import quad

    m, k, c, F0, w = 1.0, 25.0, 0.5, 2.0, 3.0
    text = one_dof(c, k, m, 0.0, 0.0, end=4.0, step=0.05) + \
        f'[[force]]\non = "m"\ntype = "sine"\namplitude = {F0}\nomega = {w}\n'
    _, result = run(text)
    # x(t) = particular X sin(w t - phi) + homogeneous fitted to x(0) = v(0) = 0, differentiated by hand
    wn, zeta = math.sqrt(k / m), c / (2 * math.sqrt(k * m))
    wd = wn * math.sqrt(1 - zeta**2)
    X = F0 / math.sqrt((k - m * w**2) ** 2 + (c * w) ** 2)
    phi = math.atan2(c * w, k - m * w**2)
    A = X * math.sin(phi)  # x(0) = 0: A - X sin(phi) = 0
    B = (zeta * wn * A - X * w * math.cos(phi)) / wd  # v(0) = 0

    def v(t):
        e = math.exp(-zeta * wn * t)
        return (X * w * math.cos(w * t - phi) + e * (-zeta * wn * (A * math.cos(wd * t) + B * math.sin(wd * t))
                                                      + wd * (-A * math.sin(wd * t) + B * math.cos(wd * t))))

    reference = quad(lambda t: F0 * math.sin(w * t) * v(t), 0.0, 4.0, epsabs=1e-15, epsrel=1e-13, limit=400)[0]
    assert result.energy.input[-1] == pytest.approx(reference, rel=1e-10)


def test_average_acceleration_newmark_keeps_the_energy_of_an_undamped_oscillator_over_1000_periods():
    """Its discrete energy is conserved exactly; explicit Euler's grows and HHT's numerical damping takes some:
    the check sees both."""
    period = 2 * math.pi / 5.0
    text = one_dof(0.0, 25.0, 1.0, 0.1, end=1000 * period, step=period / 20)
    _, newmark = run(text, "newmark")
    energy = newmark.energy
    assert energy.max_relative_residual < 1e-11
    drift = energy.residual[-1000:].mean() - energy.residual[:1000].mean()
    assert abs(drift) / (energy.kinetic[0] + energy.strain[0]) < 1e-12
    short = one_dof(0.0, 25.0, 1.0, 0.1, end=20 * period, step=period / 20)
    euler = run(short, "euler")[1].energy  # its energy grows by (1 + (w h)^2) a step: a residual of all of it
    assert euler.residual[-1] > 10 * (euler.kinetic[0] + euler.strain[0]) and euler.max_relative_residual > 0.9
    hht = run(short, "hht")[1].energy
    assert hht.residual[-1] < -1e-3 * (hht.kinetic[0] + hht.strain[0])  # energy lost to numerical damping


def test_the_energy_check_of_an_adaptive_run_follows_its_true_error():
    """The residual of DOP853 at a loose tolerance is of the size of its error against the exact solution."""
    _, exact = run("two_dof_forced")
    _, loose = run("two_dof_forced", "DOP853", rtol=1e-5, atol=1e-8)
    error = np.abs(loose.displacement - exact.displacement).max() / np.abs(exact.displacement).max()
    assert 0.1 * error < loose.energy.max_relative_residual < 10 * error


def test_energy_under_ground_jumps_books_the_jump_work_as_input():
    _, result = run("quarter_car_bump")
    assert result.energy.max_relative_residual < 1e-10
    assert result.energy.input[-1] > 0.9 * result.energy.dissipated[-1] > 0


# ------------------------------------------------------------------------------------------------ elements
def test_three_dof_forced_mass_times_acceleration_is_force_plus_element_forces(tmp_path, cli):
    """From the HDF5 file and the scenario text alone, with the sign convention: [a, b] pushes a by +T, b by -T."""
    assert cli("simulate", SCENARIOS / "three_dof_forced.toml", "-o", tmp_path, "--no-plots").exit_code == 0
    doc = tomllib.loads((SCENARIOS / "three_dof_forced.toml").read_text())
    with h5py.File(tmp_path / "three_dof_forced.h5") as f:
        dofs = [d.decode() for d in f["dof"][()]]
        masses = np.array([m["m"] for m in doc["mass"]])
        total = f["force"][()].copy()
        for kind in ("spring", "damper"):
            forces = f[f"elements/{kind}_force"][()]
            assert [c.decode().split() for c in f[f"elements/{kind}_connects"][()]] == \
                [e["connects"] for e in doc[kind]]
            for column, element in zip(forces.T, doc[kind]):
                a, b = element["connects"]
                if a != "ground":
                    total[:, dofs.index(a)] += column
                if b != "ground":
                    total[:, dofs.index(b)] -= column
        ma = f["acceleration"][()] * masses
        assert np.abs(ma - total).max() <= 1e-10 * np.abs(ma).max()
        # the reaction is what the ground adds: sum of M a minus the applied forces
        reaction = f["elements/reaction"][()][:, 0]
        assert np.abs(ma.sum(axis=1) - f["force"][()].sum(axis=1) - reaction).max() <= 1e-10 * np.abs(reaction).max()
        # tension positive: spring[1] joins m1 to m2 with k = 5
        x = f["displacement"][()]
        assert np.allclose(f["elements/spring_force"][()][:, 1], 5.0 * (x[:, 1] - x[:, 0]), rtol=0, atol=1e-14)


def test_nonlinear_element_forces_follow_their_laws():
    text = one_dof(3.0, 25.0, 1.0, 0.3, law="quadratic").replace(
        'connects = ["ground", "m"]\nk = 25.0', 'connects = ["m", "ground"]\nk = 25.0\nlaw = "cubic"\nk3 = 400.0')
    model, result = run(text)
    x, v = result.displacement[:, 0], result.velocity[:, 0]
    e = result.elements
    assert np.allclose(e.spring[:, 0], -(25.0 * x + 400.0 * x**3), rtol=1e-14, atol=1e-15)  # [m, ground]: 0 - x
    assert np.allclose(e.damper[:, 0], 3.0 * np.abs(v) * v, rtol=1e-14, atol=1e-15)  # [ground, m]: v - 0
    assert np.allclose(e.reaction, e.spring[:, 0] - e.damper[:, 0], rtol=1e-14, atol=1e-15)
    assert result.energy.max_relative_residual < 1e-6


def test_a_matrix_scene_has_only_the_reaction_and_says_so(tmp_path, cli):
    assert cli("simulate", SCENARIOS / "three_dof_matrix_forced.toml", "-o", tmp_path, "--no-plots").exit_code == 0
    with h5py.File(tmp_path / "three_dof_matrix_forced.h5") as f:
        assert sorted(f["elements"]) == ["reaction", "support"]  # support: the reaction's axis
        assert "no elements" in f["elements"].attrs["note"]
        K, C = f["model/K"][()], f["model/C"][()]
        expected = -(f["displacement"][()] @ K.T + f["velocity"][()] @ C.T).sum(axis=1)
        assert np.allclose(f["elements/reaction"][()][:, 0], expected, rtol=1e-12, atol=1e-14)


# ------------------------------------------------------------------------------------------------ export
def test_export_reads_back_bit_for_bit(tmp_path, cli):
    assert cli("simulate", SCENARIOS / "three_dof_forced.toml", "-o", tmp_path, "--no-plots").exit_code == 0
    h5 = tmp_path / "three_dof_forced.h5"
    ran = cli("export", h5)
    assert ran.exit_code == 0, ran.output
    csv = tmp_path / "three_dof_forced.csv"
    lines = csv.read_text().splitlines()
    assert lines[0].startswith("# units: s,m,m,m,m/s")
    header = lines[1].split(",")
    assert header[:5] == ["time", "displacement.m1", "displacement.m2", "displacement.m3", "velocity.m1"]
    table = np.loadtxt(csv, delimiter=",", skiprows=2)
    with h5py.File(h5) as f:
        assert np.array_equal(table[:, 0], f["time"][()])
        for name, path in (("displacement", "displacement"), ("acceleration", "acceleration"),
                           ("spring_force", "elements/spring_force"), ("reaction", "elements/reaction")):
            columns = [i for i, h in enumerate(header) if h == name or h.startswith(name + ".")]
            assert np.array_equal(table[:, columns], f[path][()].reshape(len(table), -1)), name
        assert np.array_equal(table[:, header.index("energy.residual")], f["energy/residual"][()])
    chosen = cli("export", h5, "-o", tmp_path / "x.csv", "--datasets", "velocity,energy")
    assert chosen.exit_code == 0
    assert (tmp_path / "x.csv").read_text().splitlines()[1] == (
        "time,velocity.m1,velocity.m2,velocity.m3,energy.kinetic,energy.strain,energy.dissipated,energy.input,"
        "energy.residual")
    bad = cli("export", h5, "--datasets", "bogus", "-o", tmp_path / "y.csv")
    assert bad.exit_code == 2 and "'bogus' is not in this file" in bad.stderr and not (tmp_path / "y.csv").exists()
    assert cli("export", tmp_path / "missing.h5").exit_code == 2


def test_export_of_a_sweep_is_a_row_per_member(tmp_path, cli):
    assert cli("sweep", SCENARIOS / "one_dof_regimes_sweep.toml", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    h5 = tmp_path / "one_dof_regimes_sweep_sweep.h5"
    assert cli("export", h5, "-o", tmp_path / "s.csv").exit_code == 0
    lines = (tmp_path / "s.csv").read_text().splitlines()
    assert lines[1].split(",")[:5] == ["member", "damper[0].c", "x0.m", "v0.m", "peak_displacement.m"]
    table = np.genfromtxt(tmp_path / "s.csv", delimiter=",", skip_header=2)
    with h5py.File(h5) as f:
        assert np.array_equal(table[:, 1], f["parameters/damper[0].c"][()])
        assert np.array_equal(table[:, 2], f["initial_conditions/x0"][()][:, 0])
        assert np.array_equal(table[:, 3], f["initial_conditions/v0"][()][:, 0])
        assert np.array_equal(table[:, 4], f["metrics/peak_displacement"][()][:, 0])


def test_export_of_an_initial_condition_sweep_matches_rows_to_members(tmp_path, cli):
    assert cli("sweep", SCENARIOS / "ic_underdamped.toml", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    h5 = tmp_path / "ic_underdamped_sweep.h5"
    assert cli("export", h5, "-o", tmp_path / "s.csv").exit_code == 0
    header = (tmp_path / "s.csv").read_text().splitlines()[1].split(",")
    table = np.genfromtxt(tmp_path / "s.csv", delimiter=",", skip_header=2)
    with h5py.File(h5) as f:
        x0, v0 = f["initial_conditions/x0"][()], f["initial_conditions/v0"][()]
        assert len(np.unique(np.column_stack([x0, v0]), axis=0)) == len(x0) > 1  # the members differ by them
        assert np.array_equal(table[:, header.index("x0.m")], x0[:, 0])
        assert np.array_equal(table[:, header.index("v0.m")], v0[:, 0])


def test_export_of_an_interrupted_sweep_gives_the_members_done(tmp_path, cli):
    assert cli("sweep", SCENARIOS / "one_dof_regimes_sweep.toml", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    h5 = tmp_path / "one_dof_regimes_sweep_sweep.h5"
    for done in (0, 2):
        partial = tmp_path / f"partial{done}.h5"
        partial.write_bytes(h5.read_bytes())
        with h5py.File(partial, "r+") as f:  # as an interrupted sweep leaves it: rows past members_done dropped
            f.attrs["complete"], f.attrs["members_done"] = False, done
            for name in ("success", "metrics/peak_displacement", "metrics/settling_time"):
                f[name].resize(done, axis=0)
        out = tmp_path / f"p{done}.csv"
        result = cli("export", partial, "-o", out)
        if done == 0:
            assert result.exit_code == 2 and "no member done yet" in result.stderr and "--resume" in result.stderr
            assert result.stderr.count("\n") == 1 and not out.exists()
            continue
        assert result.exit_code == 0, result.output
        assert "2 of 4 members done" in result.stdout and "--resume" in result.stdout
        table = np.genfromtxt(out, delimiter=",", skip_header=2)
        with h5py.File(h5) as f:
            assert np.array_equal(table[:, 0], [0, 1])
            assert np.array_equal(table[:, 4], f["metrics/peak_displacement"][()][:2, 0])


# ------------------------------------------------------------------------------------------------ API
def test_the_python_api_gives_what_the_cli_writes(tmp_path, cli):
    import smdcli

    result = smdcli.simulate(str(SCENARIOS / "two_dof_forced.toml"))
    assert cli("simulate", SCENARIOS / "two_dof_forced.toml", "-o", tmp_path, "--no-plots").exit_code == 0
    with h5py.File(tmp_path / "two_dof_forced.h5") as f:
        assert np.array_equal(result.displacement, f["displacement"][()])
        assert np.array_equal(result.energy.residual, f["energy/residual"][()])
    written = smdcli.write(result, tmp_path / "api.h5")
    with h5py.File(written) as f:
        assert np.array_equal(f["velocity"][()], result.velocity) and f.attrs["kind"] == "simulate"
    scenario = smdcli.load(SCENARIOS / "two_dof_forced.toml")
    again = smdcli.simulate(scenario, method="DOP853", rtol=1e-10, atol=1e-13)
    assert again.stats.method == "DOP853"
    assert np.abs(again.displacement - result.displacement).max() < 1e-8 * np.abs(result.displacement).max()
    data = result.to_dict()
    assert data["dofs"] == ["m1", "m2"] and len(data["energy"]["residual"]) == len(result.time)


def test_the_api_raises_the_cli_errors(tmp_path):
    import smdcli
    from smdcli.errors import ScenarioError, SolverFailed

    with pytest.raises(ScenarioError, match="no such file"):
        smdcli.load(tmp_path / "none.toml")
    (tmp_path / "s.toml").write_text(one_dof(0.0, end=50.0, step=0.5) + '[solver]\nmethod = "euler"\n')
    with pytest.raises(SolverFailed):
        smdcli.simulate(tmp_path / "s.toml")


def test_import_smdcli_stays_light():
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", "import smdcli, sys; print('numpy' in sys.modules)"],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_api_tour_example_runs(tmp_path):
    import runpy
    import os

    here = os.getcwd()
    os.chdir(tmp_path)
    try:
        tour = runpy.run_path(str(ROOT / "examples" / "api_tour.py"), run_name="__main__")
    finally:
        os.chdir(here)
    # what the tour prints is what the API gives: the linear scene exact, its energy closed to rounding, the
    # tighter integrator within its tolerance of it, and a file written whole
    assert tour["result"].stats.method == "exact"
    assert tour["energy"].max_relative_residual <= 1e-10
    assert 0 < tour["error"] <= 1e-6
    assert set(tour["data"]) >= {"time", "displacement", "velocity", "acceleration"}
    assert tour["path"].name == "two_dof_forced.h5"


# ------------------------------------------------------------------------------------------------ state space
def test_state_space_export_simulated_by_lsim_converges_to_smd(tmp_path, cli):
    """lsim holds the input linearly between samples: its error falls as the square of its step."""
    from scipy.io import loadmat
    from scipy.signal import lsim

    import smdcli

    assert cli("info", SCENARIOS / "two_dof_forced.toml", "--state-space", tmp_path / "ss.npz").exit_code == 0
    assert cli("info", SCENARIOS / "two_dof_forced.toml", "--state-space", tmp_path / "ss.mat").exit_code == 0
    arrays = np.load(tmp_path / "ss.npz")
    assert list(arrays["state_names"]) == ["displacement.m1", "displacement.m2", "velocity.m1", "velocity.m2"]
    assert list(arrays["input_names"]) == ["force.m1", "force.m2"]
    mat = loadmat(tmp_path / "ss.mat")
    assert list(arrays["x0"]) == [1.0, -1.0, 1.5, 1.0]  # the book's [x1 x2 v1 v2]
    assert np.array_equal(mat["A"], arrays["A"]) and np.array_equal(mat["B"], arrays["B"])
    result = smdcli.simulate(SCENARIOS / "two_dof_forced.toml")
    model = result.origin[1]
    errors = []
    for refine in (5, 10, 20):
        t = np.linspace(result.time[0], result.time[-1], (len(result.time) - 1) * refine + 1)
        _, y, _ = lsim((arrays["A"], arrays["B"], arrays["C"], arrays["D"]), model.applied_force(t), t,
                       X0=arrays["x0"])
        errors.append(np.abs(y[::refine] - result.displacement).max() / np.abs(result.displacement).max())
    assert errors[-1] < 1e-7
    assert 3.5 < errors[0] / errors[1] < 4.5 and 3.5 < errors[1] / errors[2] < 4.5  # second order


def test_state_space_of_a_bad_extension_is_a_usage_error(tmp_path, cli):
    ran = cli("info", SCENARIOS / "two_dof_forced.toml", "--state-space", tmp_path / "ss.txt")
    assert ran.exit_code == 2 and ".npz or .mat" in ran.stderr and not list(tmp_path.iterdir())


# ------------------------------------------------------------------------------------------------ expect
CHECKED = one_dof(0.4, 25.0, 1.0, 0.1, end=40.0, step=0.01) + """
[[expect]]
quantity = "peak_displacement"
dof = "m"
max = 0.05
[[expect]]
quantity = "natural_frequency"
min = 4.9
max = 5.1
[[expect]]
quantity = "energy_residual"
max = 1e-10
[[expect]]
quantity = "settling_time"
dof = "m"
max = 25.0
"""


def test_a_failing_expect_exits_1_after_writing_and_the_junit_report_names_it(tmp_path, cli):
    scenario = tmp_path / "checked.toml"
    scenario.write_text(CHECKED)
    ran = cli("simulate", scenario, "-o", tmp_path / "out", "--no-plots", "--junit", tmp_path / "report.xml")
    assert ran.exit_code == 1
    assert "FAIL expect[0] peak_displacement m = 0.1 m (max 0.05)" in ran.stdout
    assert "PASS expect[1] natural_frequency mode 1 = 5 rad/s" in ran.stdout
    with h5py.File(tmp_path / "out" / "checked.h5") as f:
        assert f["expect"].attrs["failed"] == 1
        assert f["expect/0"].attrs["value"] == pytest.approx(0.1, rel=1e-12) and not f["expect/0"].attrs["passed"]
        # settling time: 2 % of 0.1 with zeta = 0.04, wn = 5: about ln(50) / (zeta wn) = 19.6 s, measured on the grid
        settling = f["expect/3"].attrs["value"]
        assert 17.0 < settling < 19.6 and f["expect/3"].attrs["passed"]
    suite = ET.parse(tmp_path / "report.xml").getroot()
    assert suite.get("tests") == "4" and suite.get("failures") == "1"
    failures = [case for case in suite.iter("testcase") if case.find("failure") is not None]
    assert [case.get("name") for case in failures] == ["expect[0] peak_displacement m"]
    assert "measured 0.1" in failures[0].find("failure").text


def test_passing_expects_and_a_golden_check_exit_0(tmp_path, cli):
    golden = ROOT / "tests" / "golden" / "two_dof_forced.h5"
    text = (SCENARIOS / "two_dof_forced.toml").read_text()
    with h5py.File(golden) as f:
        stride = int(f.attrs["golden_stride"])
    assert stride == 1, "the golden check compares full grids"
    scenario = tmp_path / "two_dof_forced.toml"
    scenario.write_text(text + f'\n[[expect]]\nquantity = "golden"\nfile = "{golden}"\nrtol = 1e-9\natol = 1e-15\n'
                        '[[expect]]\nquantity = "energy_residual"\nmax = 1e-10\n')
    ran = cli("simulate", scenario, "-o", tmp_path / "out", "--no-plots", "--json")
    assert ran.exit_code == 0, ran.output
    import json

    checks = json.loads(ran.stdout)[0]["expect"]
    assert [c["passed"] for c in checks] == [True, True] and checks[0]["value"] < 1e-9
    assert checks[1]["units"] == "1" and checks[1]["mode"] is None and checks[1]["max"] == 1e-10


def test_the_hermite_rule_agrees_with_the_closed_form_where_the_grid_resolves_the_motion():
    """The fallback quadrature (quintic Hermite of x, v, a; 8-point Gauss) against the closed form, O(h^6)."""
    from smdcli.analysis import energy

    sc, model, grid = bundled("two_dof_forced")
    result = solve_scenario(sc, model, grid)
    closed = energy._closed_form(model, result)
    hermite = energy._hermite_gauss(model, result)
    for exact, approximate in zip(closed, hermite):
        assert np.abs(approximate - exact).max() < 1e-9 * np.abs(exact).max()


def _nodewise_hermite(model, result, points: int = 8):
    """Each output step's dissipated energy and input work by Gauss-Legendre at the nodes of the quintic Hermite
    interpolant of (x, v, a), its basis written out here: the rule the Gram form replaced, as the reference."""
    nodes, weights = np.polynomial.legendre.leggauss(points)
    s, w = 0.5 * (nodes + 1), 0.5 * weights
    slopes = np.stack([-30 * s**2 + 60 * s**3 - 30 * s**4, 1 - 18 * s**2 + 32 * s**3 - 15 * s**4,
                       (2 * s - 9 * s**2 + 12 * s**3 - 5 * s**4) / 2, 30 * s**2 - 60 * s**3 + 30 * s**4,
                       -12 * s**2 + 28 * s**3 - 15 * s**4, (3 * s**2 - 8 * s**3 + 5 * s**4) / 2], axis=1)
    t, x, v, a = result.time, result.displacement, result.velocity, result.acceleration
    h = np.diff(t)[:, None]
    dissipated, work = np.zeros(len(h)), np.zeros(len(h))
    for g in range(points):
        rate = (slopes[g, 0] * x[:-1] + slopes[g, 1] * h * v[:-1] + slopes[g, 2] * h**2 * a[:-1]
                + slopes[g, 3] * x[1:] + slopes[g, 4] * h * v[1:] + slopes[g, 5] * h**2 * a[1:]) / h
        power = np.einsum("ki,ij,kj->k", rate, np.asarray(model.C), rate)
        if model.quadratic is not None:
            power += (model.quadratic.coef * np.abs(rate @ model.quadratic.D.T) ** 3).sum(axis=1)
        dissipated += w[g] * power * h[:, 0]
        if model.signals:
            work += w[g] * ((rate @ model.B) * model.forces(t[:-1] + s[g] * h[:, 0])).sum(axis=1) * h[:, 0]
    return dissipated, work


@pytest.mark.parametrize("stem", ["three_storey_shaker", "one_dof_nonlinear_stiff", "three_dof_matrix_forced",
                                  "three_dof_free"])
def test_the_hermite_rules_gram_form_equals_gauss_at_its_nodes(stem):
    """The quadratic powers in closed form over the interpolant (a Gram form of the step's ends) against 8-point
    Gauss at its nodes, for element dampers with added [damping] and forces, a quadratic damper, a [system]'s C,
    each step to rounding (the interpolant's power is of degree 8, which 8 points integrate exactly)."""
    from smdcli.analysis import energy

    sc, model, grid = bundled(stem)
    result = solve_scenario(sc, model, grid, "rk4" if model.is_linear else None)
    assert not energy._events(model, result.time, grid[1] - grid[0])
    dissipated, work = energy._hermite_gauss(model, result)
    reference = _nodewise_hermite(model, result)
    for cumulative, steps in zip((dissipated, work), reference):
        scale = np.abs(steps).sum()
        assert scale > 0 or not model.signals
        assert np.abs(np.diff(cumulative) - steps).max() <= 1e-13 * max(scale, 1e-300)


def test_energy_of_a_nonlinear_scene_books_the_ground_jumps_inside_output_steps():
    """A cubic tyre over the plank, its edges between output points: the jump work comes from the dense output
    at each jump (the right limit), the state before it by the jump itself."""
    text = (SCENARIOS / "quarter_car_bump.toml").read_text()
    nonlinear = text.replace('[[spring]]\nconnects = ["ground", "wheel"]',
                             '[[spring]]\nconnects = ["ground", "wheel"]\nlaw = "cubic"\nk3 = 1e9', 1)
    nonlinear = nonlinear.replace("t0 = 0.5", "t0 = 0.50037")
    assert nonlinear.count("k3 = 1e9") == 1 and "t0 = 0.50037" in nonlinear
    model, result = run(nonlinear, "Radau", rtol=1e-8, atol=1e-12)
    assert [t for t, _, _ in model.jumps] == pytest.approx([0.50037, 0.90037])
    assert result.energy.max_relative_residual < 1e-7
    assert result.energy.input[-1] > 0.5 * result.energy.dissipated[-1] > 0


PLANK_NONLINEAR = (SCENARIOS / "quarter_car_bump.toml").read_text().replace(
    '[[spring]]\nconnects = ["ground", "wheel"]', '[[spring]]\nconnects = ["ground", "wheel"]\nlaw = "cubic"\nk3 = 1e8', 1
).replace("t0 = 0.5", "t0 = 0.5004").replace("duration = 0.4", "duration = 0.4003")
PULSED_DUFFING = one_dof(0.4, 25.0, 1.0, 0.0, end=6.0, step=0.05, extra="""
[[force]]
on = "m"
type = "pulse"
amplitude = 5.0
t0 = 1.01
duration = 0.52
""").replace("k = 25.0", 'k = 25.0\nlaw = "cubic"\nk3 = 400.0', 1)


@pytest.mark.parametrize("text", [PLANK_NONLINEAR, PULSED_DUFFING], ids=["ground jumps", "force pulse"])
@pytest.mark.parametrize("method", ["rk4", "newmark"])
def test_a_fixed_step_run_of_a_nonlinear_scene_is_judged_across_jumps_inside_output_steps(text, method):
    """The Hermite rule spans no discontinuity: a step a force edge or a ground jump interrupts is re-integrated
    from the run's state at its start, so the residual is the method's own error (it was the whole jump's
    energy, 1.0, for the plank), within a small factor of the true error from a tight DOP853 run."""
    model, result = run(text, method)
    assert "Hermite" in result.energy.quadrature and (model.jumps or model.breakpoints(0.0, 10.0).size)
    _, reference = run(text, "DOP853", rtol=1e-12, atol=1e-14)
    error = np.abs(result.displacement - reference.displacement).max() / np.abs(reference.displacement).max()
    residual = result.energy.max_relative_residual
    assert reference.energy.max_relative_residual < 1e-9
    assert error / 10 < residual < 10 * error, (residual, error)


def test_a_large_model_keeps_its_modes_in_data_sets_not_attributes(tmp_path, cli):
    """HDF5 caps an object's header (its attributes) at 64 KB: beyond 256 modes the per-mode arrays are data sets
    only, so a file holds a model of any size (10,000 masses overflowed it before)."""
    n = 300
    lines = ["[time]", "end = 0.1", "step = 0.01"]
    for i in range(n):
        lines += ["[[mass]]", f'name = "m{i}"', "m = 1.0"]
    for i in range(n):
        lines += ["[[spring]]", f'connects = ["{"ground" if i == 0 else f"m{i - 1}"}", "m{i}"]', "k = 100.0"]
    lines += ["[[force]]", 'on = "m0"', 'type = "sine"', "amplitude = 1.0", "omega = 3.0"]
    scene = tmp_path / "chain.toml"
    scene.write_text("\n".join(lines) + "\n")
    assert cli("simulate", scene, "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    with h5py.File(tmp_path / "chain.h5") as f:
        modes = f["model/modes"]
        assert all(np.size(value) <= 256 for value in modes.attrs.values())
        assert modes["natural_frequencies_rad_s"].shape == (n,) and modes["regimes"].shape == (n,)
        assert modes["regimes"][0].decode() == "undamped"


@pytest.mark.parametrize("stem", ["friction_isolated_building", "elastoplastic_record", "bouncing_ball",
                                  "vibro_impact_gap"])
def test_export_holds_every_time_series_of_the_file_and_its_energy_balances(tmp_path, cli, stem):
    """Every data set on the time axis (friction and stop forces, hysteretic, friction, impact and contact energy,
    plastic deformation, the ground's motion) is a column equal to the file's, and the energy columns close the
    balance the file states: input = the stored terms' change + every dissipated term + residual. The export used
    to drop every nonsmooth data set, so its energy columns did not balance."""
    assert cli("simulate", SCENARIOS / f"{stem}.toml", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    h5 = tmp_path / f"{stem}.h5"
    assert cli("export", h5).exit_code == 0
    csv = tmp_path / f"{stem}.csv"
    header = csv.read_text().splitlines()[1].split(",")
    table = np.loadtxt(csv, delimiter=",", skiprows=2, ndmin=2)
    exported = set()
    with h5py.File(h5) as f:
        steps = len(f["time"])

        def check(path, obj):
            if not isinstance(obj, h5py.Dataset) or path == "time" or obj.shape[:1] != (steps,) or \
                    path.split("/")[0] in ("model", "events") or obj.dtype.kind != "f" or obj.size == 0:
                return
            from smdcli.commands.export import SERIES

            name = next((n for n, p, _ in SERIES if p == path), path.replace("/", "."))
            columns = [i for i, h in enumerate(header) if h == name or h.startswith(name + ".") and
                       h.count(".") == name.count(".") + 1]
            assert columns, f"{path} is not exported"
            assert np.array_equal(table[:, columns], obj[()].reshape(steps, -1)), path
            exported.add(path)

        f.visititems(check)
        terms = {name.split(".", 1)[1]: table[:, i] for i, name in enumerate(header) if name.startswith("energy.")}
        stored = sum(terms.get(name, 0.0) for name in ("kinetic", "strain", "contact"))
        lost = sum(terms.get(name, 0.0) for name in ("dissipated", "hysteretic", "friction", "impact"))
        balance = stored - stored[0] + lost - terms["input"]
        scale = max(np.abs(terms["input"]).max(), np.abs(stored).max())
        assert np.abs(balance - terms["residual"]).max() <= 1e-12 * scale
    assert any(p.startswith("energy/") and p.split("/")[1] not in ("kinetic", "strain", "dissipated", "input",
                                                                     "residual") for p in exported)


@pytest.mark.parametrize("stem", ["shear_frame_bilinear", "elastoplastic_record", "bouc_wen_multisine"])
def test_model_K_of_a_hysteretic_scene_is_the_scene_at_rest_as_its_modes_are(tmp_path, cli, stem):
    """/model/K held only the stamped linear part (a bilinear spring's b k, nothing of an elastoplastic one) while
    smd info and /model/modes use the elastic k: its eigenvalues now are the modes the file lists."""
    assert cli("simulate", SCENARIOS / f"{stem}.toml", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    with h5py.File(tmp_path / f"{stem}.h5") as f:
        K, M = f["model/K"][()], f["model/M"][()]
        listed = f["model/modes/natural_frequencies_rad_s"][()]
        assert "at rest" in f["model/K"].attrs["description"]
    omegas = np.sort(np.sqrt(np.linalg.eigvals(np.linalg.solve(M, K)).real))
    np.testing.assert_allclose(omegas, np.sort(listed), rtol=1e-10)
