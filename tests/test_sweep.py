"""smd sweep: value specs, parameter paths, batched families against independent solutions,
frequency responses against the book's formulas (9-34)/(9-35), the nonlinear jump, HDF5 layout."""

import math

import h5py
import numpy as np
import pytest
from conftest import SCENARIOS, force_block, model_of, one_dof

from smdcli import scenario
from smdcli.errors import ScenarioError, UsageError
from smdcli.model import time_grid
from smdcli.solvers.exact.accurate_expm import expm_stack
from smdcli.solvers.base import Tolerances
from smdcli.solvers.registry import solver_class
from smdcli.sweep import (build_family, frequency_response, metrics, parse_frequency, parse_ic,
                          parse_values, read_spec, set_parameter, solve_family)


def family_of(text, **cli):
    sc = scenario.parse(text, "test.toml")
    return build_family(sc, read_spec(sc, cli))


# ------------------------------------------------------------------ specs

@pytest.mark.parametrize("spec, expected", [
    ("0:1:0.2", [0, 0.2, 0.4, 0.6, 0.8, 1.0]),
    ("0:1.2:0.2", [0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2]),
    ("5:1:-2", [5, 3, 1]),
    ("1:3", [1, 2, 3]),
    ("linspace(0, 1, 5)", [0, 0.25, 0.5, 0.75, 1]),
    ("logspace(0, 2, 3)", [1, 10, 100]),
    ("0, 2, 13, 10", [0, 2, 13, 10]),
    ([0.0, 2.0], [0, 2]),
])
def test_value_specs(spec, expected):
    np.testing.assert_allclose(parse_values(spec), expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("spec", ["0:1:-0.1", "0:1:0", "abc", "linspace(0, 1)", "linspace(0, 1, 0)", "", "1:2:3:4",
                                  "0:1e9:1e-3", "nan, 1"])
def test_bad_value_specs_are_refused(spec):
    with pytest.raises(ValueError):
        parse_values(spec)


def test_frequency_in_hertz_becomes_rad_per_s():
    omega, unit = parse_frequency("0:2:1 Hz")
    assert unit == "Hz"
    np.testing.assert_allclose(omega, [0, 2 * math.pi, 4 * math.pi])
    with pytest.raises(ValueError):
        parse_frequency("-1:1:1")


def test_initial_condition_specs():
    x0, v0 = parse_ic("x0=0.1,v0=-1", ("m",))
    assert (x0[0], v0[0]) == (0.1, -1.0)
    x0, v0 = parse_ic("m2.v0=2", ("m1", "m2"))
    assert list(x0) == [0, 0] and list(v0) == [0, 2]
    for bad in ("x0=0.1", "m3.x0=1", "m1.a0=1", "m1.x0=inf", "m1.x0=abc"):
        with pytest.raises(ValueError):
            parse_ic(bad, ("m1", "m2"))


def test_parameter_paths_edit_the_document():
    doc = {"time": {"end": 1.0}, "mass": [{"name": "m1", "m": 1.0}, {"name": "m2", "m": 2.0}],
           "force": [{"on": "m1", "type": "sine", "frequency": 1.0, "amplitude": 1.0}],
           "system": {"K": [[2.0, -1.0], [-1.0, 2.0]]}}
    set_parameter(doc, "mass.m2.m", 5.0)
    set_parameter(doc, "mass[0].x0", 0.3)
    set_parameter(doc, "force[0].omega", 7.0)
    set_parameter(doc, "time.end", 9.0)
    set_parameter(doc, "system.K[0][1]", -0.5)
    assert doc["mass"][1]["m"] == 5.0 and doc["mass"][0]["x0"] == 0.3 and doc["time"]["end"] == 9.0
    assert doc["force"][0]["omega"] == 7.0 and "frequency" not in doc["force"][0]
    assert doc["system"]["K"][0][1] == doc["system"]["K"][1][0] == -0.5
    for bad in ("mass.m3.m", "spring[0].k", "mass[5].m", "force[0].on", "time..end", "[0].c"):
        with pytest.raises(UsageError):
            set_parameter(doc, bad, 1.0)


def test_a_value_that_makes_a_bad_scene_names_the_field():
    with pytest.raises(ScenarioError, match=r"mass\[0\]\.m: with mass\.m\.m = -1: expected a number > 0"):
        family_of(one_dof(1.0), parameter=("mass.m.m",), values=("-1, 1",))
    with pytest.raises(ScenarioError, match=r"unknown key"):
        family_of(one_dof(1.0), parameter=("damper[0].q",), values=("1",))


# ---------------------------------------------------------- time families

def test_batched_expm_matches_scipy():
    from scipy.linalg import expm

    rng = np.random.default_rng(1)
    A = rng.normal(size=(40, 4, 4)) * rng.uniform(0.01, 30, size=(40, 1, 1))
    reference = expm(A)
    assert np.abs(expm_stack(A) - reference).max() / np.abs(reference).max() < 1e-12


def test_four_regimes_match_the_closed_form():
    """The book's Figure 9-2: D = 0, 2, 13, 10 against the closed form of each regime (a different formula)."""
    sc = scenario.load(SCENARIOS / "one_dof_regimes_sweep.toml")
    family = build_family(sc, read_spec(sc, {}))
    result = solve_family(family)
    assert result.how.startswith("one batched exact recurrence")
    grid = time_grid(sc.time)
    for s in range(len(family)):
        reference = solver_class("closed_form")().solve(family.model(s), grid, Tolerances())
        assert np.abs(result.displacement[s] - reference.displacement).max() < 1e-13
        assert np.abs(result.velocity[s] - reference.velocity).max() < 1e-12
        assert np.abs(result.acceleration[s] - reference.acceleration).max() < 1e-10
    assert family.labels[0] == "No damping: zeta = 0"


def book_smdsyssim(M, D, S, u0, du0, t):
    """SMDsysSim of the book, transcribed (its float-equality branches included)."""
    wn = math.sqrt(S / M)
    ksi = 0.5 * (D / M) / wn
    if ksi == 0:
        return u0 * np.cos(wn * t) + du0 / wn * np.sin(wn * t)
    if 0 < ksi < 1:
        wd = wn * math.sqrt(1 - ksi**2)
        return np.exp(-ksi * wn * t) * (u0 * np.cos(wd * t) + (u0 * ksi * wn + du0) * np.sin(wd * t) / wd)
    if ksi > 1:
        r1 = (-ksi - math.sqrt(ksi**2 - 1)) * wn
        r2 = (-ksi + math.sqrt(ksi**2 - 1)) * wn
        A = (-du0 + (-ksi + math.sqrt(ksi**2 - 1)) * u0 * wn) / (2 * wn * math.sqrt(ksi**2 - 1))
        B = (du0 + (ksi + math.sqrt(ksi**2 - 1)) * u0 * wn) / (2 * wn * math.sqrt(ksi**2 - 1))
        return A * np.exp(r1 * t) + B * np.exp(r2 * t)
    return (u0 + (du0 + wn * u0) * t) * np.exp(-wn * t)


@pytest.mark.parametrize("name, D", [("ic_underdamped", 5.0), ("ic_critical", 10.0), ("ic_overdamped", 13.0)])
def test_initial_condition_studies_match_the_books_code(name, D):
    """Figure 9-4: each panel's three initial conditions against the book's own SMDsysSim."""
    sc = scenario.load(SCENARIOS / f"{name}.toml")
    family = build_family(sc, read_spec(sc, {}))
    result = solve_family(family)
    t = time_grid(sc.time)
    np.testing.assert_allclose(t, np.arange(0, 2.5 + 1e-9, 0.05), atol=1e-12)
    assert len(family) == 3
    for s in range(3):
        u0, du0 = family.x0[s, 0], family.v0[s, 0]
        expected = book_smdsyssim(1.0, D, 25.0, u0, du0, t)
        assert np.abs(result.displacement[s, :, 0] - expected).max() < 1e-12


def test_two_parameter_grid_matches_member_by_member_exact_solves():
    text = one_dof(1.0, end=8.0, step=0.01, extra=force_block("sine", amplitude=2.0, omega=3.0)
                   + force_block("step", amplitude=1.0, t0=2.004))
    family = family_of(text, parameter=("spring[0].k", "mass.m.m"), values=("10, 40, 90", "0.5:2:0.5"))
    assert family.shape == (3, 4) and len(family) == 12
    result = solve_family(family)
    grid = time_grid(family.scenario.time)
    for s in (0, 5, 11):
        k, m = map(float, family.values[s])
        _, model, _ = model_of(one_dof(1.0, k=k, m=m, end=8.0, step=0.01,
                                       extra=force_block("sine", amplitude=2.0, omega=3.0)
                                       + force_block("step", amplitude=1.0, t0=2.004)))
        reference = solver_class("exact")().solve(model, grid, Tolerances())
        assert np.abs(result.displacement[s] - reference.displacement).max() < 1e-12
        assert np.abs(result.acceleration[s] - reference.acceleration).max() < 1e-10


def test_force_parameter_family_is_batched_with_its_own_forces():
    text = one_dof(0.5, end=10.0, step=0.01, extra=force_block("sine", amplitude=1.0, omega=2.0))
    family = family_of(text, parameter=("force[0].omega",), values=("1, 4, 5, 7",))
    assert family.scenarios is not None
    result = solve_family(family)
    assert "its own forces" in result.how
    for s, w in enumerate((1, 4, 5, 7)):
        _, model, grid = model_of(one_dof(0.5, end=10.0, step=0.01, extra=force_block("sine", amplitude=1.0, omega=w)))
        reference = solver_class("exact")().solve(model, grid, Tolerances())
        assert np.abs(result.displacement[s] - reference.displacement).max() < 1e-12


def test_nonlinear_coefficient_family_runs_on_threads_and_matches_single_runs():
    """A swept quadratic damping is one model with interpolated coefficients, solved in-process by the kernels."""
    from smdcli.solvers.dispatch import solve

    text = one_dof(0.5, law="quadratic", end=3.0, step=0.01)
    family = family_of(text, parameter=("damper[0].c",), values=("0.5, 5, 50",))
    assert family.scenarios is None and np.allclose(family.quadratic_coef[:, 0], [0.5, 5, 50], rtol=1e-15)
    result = solve_family(family, workers=2)
    assert result.how.startswith("threads")
    for s in range(3):
        sc = family.member_scenario(s)
        _, model, grid = model_of(sc.text)
        single = solve(model, grid, "auto", Tolerances(rtol=sc.solver.rtol, atol=sc.solver.atol))
        peak = np.abs(single.displacement).max()
        # The interpolated coefficient may differ from the written one by a rounding: both runs are within
        # their stated accuracy of the truth.
        bound = (result.stated_accuracy[s] + single.stats.stated_accuracy) * peak
        assert np.abs(result.displacement[s] - single.displacement).max() <= bound


def test_nonlinear_family_of_force_shapes_runs_in_a_process_pool_and_matches_single_runs():
    from smdcli.solvers.dispatch import solve

    text = one_dof(0.5, law="quadratic", end=3.0, step=0.01, extra=force_block("sine", amplitude=1.0, omega=2.0))
    family = family_of(text, parameter=("force[0].omega",), values=("1, 3",))
    result = solve_family(family, workers=2)
    assert result.how.startswith("process pool")
    for s in range(2):
        sc = family.member_scenario(s)
        _, model, grid = model_of(sc.text)
        single = solve(model, grid, "auto", Tolerances(rtol=sc.solver.rtol, atol=sc.solver.atol))
        np.testing.assert_array_equal(result.displacement[s], single.displacement)


def test_time_parameter_gives_padded_member_grids():
    family = family_of(one_dof(1.0, end=1.0, step=0.1), parameter=("time.end",), values=("1, 2",))
    result = solve_family(family, workers=1)
    assert result.time.shape == (2, 21)
    assert np.isnan(result.time[0, 11:]).all() and result.time[1, -1] == pytest.approx(2.0)


def test_metrics_against_closed_forms():
    """Peak, RMS, 2 % settling time and ground force of an overdamped decay, from its closed form."""
    from scipy.integrate import quad
    from scipy.optimize import brentq

    family = family_of(one_dof(13.0, end=6.0, step=0.001), parameter=("damper[0].c",), values=("13, 26",))
    result = solve_family(family)
    values = metrics(family, result)
    for s, c in enumerate((13.0, 26.0)):
        x = lambda t: book_smdsyssim(1.0, c, 25.0, 0.1, 0.0, np.asarray(t))  # noqa: E731
        assert values["peak_displacement"][s, 0] == pytest.approx(0.1, abs=1e-15)
        rms = math.sqrt(quad(lambda t: x(t) ** 2, 0, 6.0, limit=200)[0] / 6.0)
        assert values["rms_displacement"][s, 0] == pytest.approx(rms, rel=1e-5)
        band = 0.02 * (0.1 - x(6.0))
        settle = brentq(lambda t: abs(x(t) - x(6.0)) - band, 0.01, 5.9)
        assert abs(values["settling_time"][s, 0] - settle) <= 0.001 + 1e-12
        t, h = result.time, 1e-6
        v = (x(t + h) - x(t - h)) / (2 * h)
        ground = np.abs(25.0 * x(t) + c * v).max()
        assert values["peak_ground_force"][s, 0] == pytest.approx(ground, rel=1e-8)
    undamped = family_of(one_dof(0.0, end=5.0), parameter=("damper[0].c",), values=("0",))
    assert np.isnan(metrics(undamped, solve_family(undamped))["settling_time"][0, 0])


# ------------------------------------------------------- frequency response

def test_normalized_response_matches_the_books_formulas():
    """Equations (9-34) and (9-35) with the script's M = 2.5, S = 25, and a fine grid through r = 1."""
    sc = scenario.load(SCENARIOS / "frequency_response_zeta.toml")
    spec = read_spec(sc, {"frequency": "linspace(0, 10, 2001)"})
    family = build_family(sc, spec)
    response = frequency_response(family)
    r = response.omega / math.sqrt(25 / 2.5)
    for s, zeta in enumerate(np.arange(6) * 0.2):
        magnitude = 1 / np.sqrt((1 - r**2) ** 2 + (2 * zeta * r) ** 2)
        theta = np.arctan2(2 * zeta * r, 1 - r**2)
        ok = np.isfinite(magnitude)
        assert np.abs(response.amplitude[s, ok, 0] * 25 / magnitude[ok] - 1).max() < 1e-10
        assert np.abs(response.phase[s, :, 0] - theta).max() < 1e-10
        assert 0 <= response.phase[s].min() and response.phase[s].max() <= math.pi
    damped = [p for p in response.peaks if math.isfinite(p["amplitude"])]
    for p in damped:  # the peak of (9-34) is at r = sqrt(1 - 2 zeta^2), of height 1 / (2 zeta sqrt(1 - zeta^2))
        zeta = family.values[p["member"], 0]
        assert p["omega"] / math.sqrt(10) == pytest.approx(math.sqrt(1 - 2 * zeta**2), rel=1e-6)
        assert p["amplitude"] * 25 == pytest.approx(1 / (2 * zeta * math.sqrt(1 - zeta**2)), rel=1e-10)
    assert [family.values[p["member"], 0] for p in damped] == pytest.approx([0.2, 0.4, 0.6])
    undamped = [p for p in response.peaks if not math.isfinite(p["amplitude"])]
    assert len(undamped) == 1 and undamped[0]["omega"] == pytest.approx(math.sqrt(10), rel=1e-12)


def test_normalized_file_holds_the_books_axes(cli, tmp_path):
    result = cli("sweep", SCENARIOS / "one_dof_harmonic.toml", "--frequency", "0:10:0.2", "--normalized",
                 "--param", "zeta", "--values", "0:1.2:0.2", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "one_dof_harmonic_sweep.h5") as f:
        r, amplitude, phase = f["frequency_ratio"][()], f["normalized_amplitude"][()][..., 0], f["phase"][()][..., 0]
        zeta = f["parameters/zeta"][()]
    np.testing.assert_allclose(zeta, [0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2], atol=1e-15)
    expected = 1 / np.sqrt((1 - r**2) ** 2 + (2 * zeta[:, None] * r) ** 2)
    assert np.abs(amplitude / expected - 1).max() < 1e-10
    assert np.abs(phase - np.arctan2(2 * zeta[:, None] * r, 1 - r**2)).max() < 1e-10


def test_two_dof_receptance_matches_a_long_exact_simulation():
    """Amplitude and phase of both masses at three frequencies against the steady state of a time simulation."""
    sc = scenario.load(SCENARIOS / "two_dof_frequency_response.toml")
    family = build_family(sc, read_spec(sc, {"frequency": "2, 5, 8.3"}))
    response = frequency_response(family)
    for f, w in enumerate((2.0, 5.0, 8.3)):
        period = 2 * math.pi / w
        text = sc.text.replace("omega = 10.0", f"omega = {w!r}").replace("amplitude = 3.3", "amplitude = 1.0")
        text = text.replace("end = 5.0\nstep = 0.005", f"end = {400 * period!r}\npoints = 40001")
        _, model, grid = model_of(text)
        run = solver_class("exact")().solve(model, grid, Tolerances())
        last = grid >= grid[-1] - period
        basis = np.stack([np.cos(w * grid[last]), np.sin(w * grid[last])], axis=1)
        for j in range(2):
            (a, b), *_ = np.linalg.lstsq(basis, run.displacement[last, j], rcond=None)
            assert response.amplitude[0, f, j] == pytest.approx(math.hypot(a, b), rel=1e-8)
            lag = math.atan2(b, a) - math.pi / 2  # x = X cos(w t - pi/2 - lag) behind F = sin(w t)
            assert math.cos(response.phase[0, f, j] - lag) == pytest.approx(1.0, abs=1e-12)
    full = frequency_response(build_family(sc, read_spec(sc, {})))
    M, C, K = np.diag([5.0, 3.0]), np.array([[3.0, -1.0], [-1.0, 4.0]]), np.array([[90.0, -90.0], [-90.0, 175.0]])

    def amplitude(w, j):
        return abs(np.linalg.solve(K - w**2 * M + 1j * w * C, [1.0, 0.0])[j])

    for j, dof in enumerate(("m1", "m2")):
        peaks = sorted((p for p in full.peaks if p["dof"] == dof), key=lambda p: p["omega"])
        assert len(peaks) == 2
        for p, wn in zip(peaks, (2.72023, 8.30193)):  # near each mode's natural frequency ...
            assert p["omega"] == pytest.approx(wn, rel=0.05)
            assert p["amplitude"] == pytest.approx(amplitude(p["omega"], j), rel=1e-12)
            for dw in (-1e-4, 1e-4):  # ... and a maximum of |H|, solved directly
                assert amplitude(p["omega"] + dw, j) < p["amplitude"]


def test_measured_response_of_a_linear_scene_agrees_with_the_exact_one():
    sc = scenario.load(SCENARIOS / "frequency_response_zeta.toml")
    family = build_family(sc, read_spec(sc, {"frequency": "1, 3, 3.2, 6", "values": ("0.1, 0.5",), "measure": True,
                                             "direction": "up"}))
    response = frequency_response(family, workers=1)
    amplitude, lag = response.measured["up"]
    assert response.difference < 1e-7
    assert np.abs(lag - response.phase).max() < 1e-6
    assert response.steady["up"].all()


def harmonic_balance_amplitudes(w, m=1.0, k=25.0, c=0.5, k3=100.0, f0=2.5):
    """First-harmonic balance of the Duffing oscillator: the real roots A of
    [(k - m w^2 + 3/4 k3 A^2)^2 + (c w)^2] A^2 = f0^2, a cubic in A^2."""
    a = 0.75 * k3
    b = k - m * w**2
    coeffs = [a**2, 2 * a * b, b**2 + (c * w) ** 2, -f0**2]
    roots = np.roots(coeffs)
    return sorted(math.sqrt(r.real) for r in roots if abs(r.imag) < 1e-9 and r.real > 0)


def test_duffing_jump_up_and_down_against_harmonic_balance():
    sc = scenario.load(SCENARIOS / "duffing_frequency_response.toml")
    family = build_family(sc, read_spec(sc, {"frequency": "4:8:0.25"}))
    response = frequency_response(family, workers=2)
    up, down = response.measured["up"][0][0, :, 0] * 2.5, response.measured["down"][0][0, :, 0] * 2.5
    assert response.steady["up"].all() and response.steady["down"].all()
    for f, w in enumerate(response.omega):
        roots = harmonic_balance_amplitudes(w)
        if len(roots) == 3:  # the hysteresis band: up on the large branch, down on the small one
            assert up[f] == pytest.approx(roots[-1], rel=0.03)
            assert down[f] == pytest.approx(roots[0], rel=0.03)
            assert up[f] > 3 * down[f]
        else:
            assert up[f] == pytest.approx(roots[0], rel=0.03)
            assert up[f] == pytest.approx(down[f], rel=1e-6)
    assert sum(len(harmonic_balance_amplitudes(w)) == 3 for w in response.omega) >= 4


# ------------------------------------------------------------------ files

def test_sweep_hdf5_layout(cli, tmp_path):
    result = cli("sweep", SCENARIOS / "one_dof_regimes_sweep.toml", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    assert "one batched exact recurrence over 4 members" in result.stdout
    with h5py.File(tmp_path / "one_dof_regimes_sweep_sweep.h5") as f:
        assert f.attrs["kind"] == "sweep" and f.attrs["sweep_kind"] == "parameter"
        assert f["displacement"].shape == (4, 101, 1)
        assert [d[0].name for d in f["displacement"].dims] == ["/member", "/time", "/dof"]
        np.testing.assert_array_equal(f["parameters/damper[0].c"][()], [0, 2, 13, 10])
        assert f["metrics/settling_time"].shape == (4, 1)
        assert np.isnan(f["metrics/settling_time"][0, 0])  # undamped: never settles
        assert [s.decode() for s in f["label"][()]][2] == "Overdamped: zeta > 1"
    for png in ("displacement", "metric"):
        assert (tmp_path / f"one_dof_regimes_sweep_sweep_{png}.png").stat().st_size > 10_000


def test_frequency_sweep_files_and_listed_peaks(cli, tmp_path):
    result = cli("sweep", SCENARIOS / "two_dof_frequency_response.toml", "-o", tmp_path)
    assert result.exit_code == 0, result.output
    assert "resonance peaks" in result.stdout and "m2 at" in result.stdout
    with h5py.File(tmp_path / "two_dof_frequency_response_sweep.h5") as f:
        assert f["amplitude"].shape == (1, 1201, 2) and f["phase"].shape == (1, 1201, 2)
        assert [d[0].name for d in f["amplitude"].dims] == ["/member", "/frequency", "/dof"]
        assert len(f["peaks/omega"]) == 4
    assert (tmp_path / "two_dof_frequency_response_sweep_frequency.png").exists()


def test_two_parameter_cli_writes_a_heat_map(cli, tmp_path):
    result = cli("sweep", SCENARIOS / "one_dof_underdamped.toml", "--param", "spring[0].k", "--values", "linspace(5,50,6)",
                 "--param", "damper[0].c", "--values", "0:12:3", "--metric", "settling_time", "-o", tmp_path, "--json")
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "one_dof_underdamped_sweep.h5") as f:
        assert list(f.attrs["grid_shape"]) == [6, 5]
        assert f["metrics/settling_time"].shape == (30, 1)
    assert (tmp_path / "one_dof_underdamped_sweep_heatmap.png").exists()


@pytest.mark.parametrize("args, message", [
    (["--param", "damper[0].c", "--values", "0:1:-1"], "--values: expected numbers"),
    (["--param", "damper[9].c", "--values", "1"], "has no entry [9] (the scenario has damper[0] only)"),
    (["--param", "zeta", "--values", "0.1", "--frequency", "0:5:1", "--normalized"], None),
    (["--values", "1"], "expected one value spec per parameter"),
    (["--frequency", "0:1:1", "--normalized"], None),
    (["--param", "mass.m.m", "--values", "1,-1"], "expected a number > 0"),
    (["--ic", "x0=1,v9=2"], "expected x0=VALUE"),
    (["--metric", "peak_displacment"], "did you mean 'peak_displacement'"),
    (["--method", "ode99", "--ic", "x0=1"], "unknown method"),
    (["--param", "spring[0].k", "--values", "linspace(1,2,100000000000)"], "expected 1 to 100000"),
    (["--method", "RK45", "--frequency", "1:2:1"], "--method: does not apply to a frequency response"),
    ([], "nothing to sweep"),
])
def test_bad_sweep_input_is_exit_2_and_writes_nothing(cli, tmp_path, args, message):
    target = SCENARIOS / ("two_dof_forced.toml" if message is None else "one_dof_underdamped.toml")
    result = cli("sweep", target, *args, "-o", tmp_path / "out")
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and len(result.stderr.strip().splitlines()) == 1
    if message:
        assert message in result.stderr
    assert not (tmp_path / "out").exists()


def test_a_sweep_of_another_kind_into_the_same_folder_says_what_it_replaced_and_leaves_no_stale_plot(tmp_path, cli):
    """A parameter sweep written where a frequency response was replaced its file silently and left the
    magnitude-and-phase plot of a response the folder no longer held."""
    import json

    scene = SCENARIOS / "one_dof_harmonic.toml"
    assert cli("sweep", scene, "--frequency", "0:10:0.5", "-o", tmp_path, "-q").exit_code == 0
    assert (tmp_path / "one_dof_harmonic_sweep_frequency.png").exists()
    ran = cli("sweep", scene, "--param", "spring[0].k", "--values", "20,30", "-o", tmp_path, "--json")
    assert ran.exit_code == 0, ran.output
    replaced = json.loads(ran.stdout)["replaced"]
    assert "held a frequency sweep, now this parameter sweep" in replaced
    assert "one_dof_harmonic_sweep_frequency.png" in replaced
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one_dof_harmonic_sweep.h5",
                                                          "one_dof_harmonic_sweep_displacement.png",
                                                          "one_dof_harmonic_sweep_metric.png"]
    with h5py.File(tmp_path / "one_dof_harmonic_sweep.h5") as f:
        assert f.attrs["sweep_kind"] == "parameter"
    again = cli("sweep", scene, "--param", "spring[0].k", "--values", "20,40", "-o", tmp_path, "--json")
    assert "replaced" not in json.loads(again.stdout)  # the same kind again: nothing to say
