"""Support motion ([ground_motion]): closed-form transmissibility, independent solves of the relative-motion
equation, jumps of a displacement pulse, the ground's own integrated motion, the file layout, spectra of a
scenario's record."""

import functools
import json

import h5py
import numpy as np
import pytest
from conftest import ROOT, SCENARIOS, model_of
from test_event_sensitivity import RESTING_ON_A_STOP, UNFORCED_STOREY, ground_pulse
from scipy.integrate import solve_ivp

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

ONE_DOF = """
[time]
end = {end}
step = {step}
[[mass]]
name = "m"
m = {m}
[[spring]]
connects = ["ground", "m"]
k = {k}
[[damper]]
connects = ["ground", "m"]
c = {c}
[ground_motion]
quantity = "displacement"
type = "sine"
amplitude = {U}
omega = {w}
"""


def closed_form_transmissibility(r, zeta):
    return np.sqrt((1 + (2 * zeta * r) ** 2) / ((1 - r**2) ** 2 + (2 * zeta * r) ** 2))


def steady_amplitude(t, x, w):
    """Amplitude of the harmonic at w (with an offset) fitted by least squares to samples: exact for a steady sine."""
    basis = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(basis, x, rcond=None)
    return float(np.hypot(coef[0], coef[1]))


@pytest.mark.parametrize("zeta", [0.1, 0.3, 0.7])
@pytest.mark.parametrize("r", [0.3, 0.9, 1.0, np.sqrt(2), 2.5, 6.0])
def test_steady_absolute_amplitude_is_the_closed_form_transmissibility(tmp_path, cli, r, zeta):
    m, k, U = 2.0, 200.0, 0.01
    wn = np.sqrt(k / m)
    w = r * wn
    c = 2 * zeta * np.sqrt(k * m)
    window = 10 * 2 * np.pi / w  # ten periods, fitted after the transient has decayed by e^-30
    end = 30.0 / (zeta * wn) + window
    path = tmp_path / "base.toml"
    path.write_text(ONE_DOF.format(end=end, step=end / 20000, m=m, k=k, c=c, U=U, w=w))
    result = cli("simulate", path, "-o", tmp_path, "--no-plots")
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "base.h5") as f:
        t, x = f["time"][()], f["absolute_displacement"][:, 0]
    tail = t >= t[-1] - window
    measured = steady_amplitude(t[tail], x[tail], w) / U
    expected = closed_form_transmissibility(r, zeta)
    assert abs(measured - expected) <= 1e-8 * expected, (measured, expected)


REFERENCE_METHOD = "DOP853"


def relative_motion_reference(M, C, K, a_g, t, x0=None, v0=None, cubic=None):
    """M y'' + C y' + K y (+ k3 y^3 on DOF 0's ground spring) = -M 1 a_g(t) by scipy's DOP853 at rtol 1e-13 (its
    Radau at rtol 1e-12 agreed to 1e-12 and took 25 times as long)."""
    n = len(M)
    Minv = np.linalg.inv(M)
    ones = np.ones(n)

    def rhs(time, z):
        y, v = z[:n], z[n:]
        f = -M @ ones * a_g(time) - C @ v - K @ y
        if cubic is not None:
            f[0] -= cubic * y[0] ** 3
        return np.concatenate([v, Minv @ f])

    z0 = np.concatenate([np.zeros(n) if x0 is None else x0, np.zeros(n) if v0 is None else v0])
    sol = solve_ivp(rhs, (t[0], t[-1]), z0, method=REFERENCE_METHOD, t_eval=t, rtol=1e-13, atol=1e-16)
    assert sol.success
    return sol.y[:n].T


def test_harmonic_ground_displacement_matches_a_tight_solve_of_the_relative_equation(tmp_path, cli):
    U, w = 0.02, 7.0
    path = tmp_path / "base.toml"
    path.write_text(ONE_DOF.format(end=6.0, step=0.005, m=1.5, k=120.0, c=1.2, U=U, w=w))
    assert cli("simulate", path, "-o", tmp_path, "--no-plots").exit_code == 0
    with h5py.File(tmp_path / "base.h5") as f:
        t, y = f["time"][()], f["displacement"][()]
        ground = {q: f[f"ground/{q}"][()] for q in ("displacement", "velocity", "acceleration")}
        absolute = f["absolute_displacement"][()]
    ref = relative_motion_reference(np.array([[1.5]]), np.array([[1.2]]), np.array([[120.0]]),
                                    lambda s: -U * w * w * np.sin(w * s), t)
    assert np.abs(y - ref).max() <= 1e-8 * np.abs(ref).max()
    np.testing.assert_allclose(ground["displacement"], U * np.sin(w * t), atol=1e-15)
    np.testing.assert_allclose(ground["velocity"], U * w * np.cos(w * t), atol=1e-14)
    np.testing.assert_allclose(ground["acceleration"], -U * w * w * np.sin(w * t), atol=1e-13)
    np.testing.assert_allclose(absolute, y + ground["displacement"][:, None], atol=1e-17)


CHAIN = """
[time]
end = 5.0
step = 0.01
[[mass]]
name = "a"
m = 2.0
x0 = 0.01
[[mass]]
name = "b"
m = 1.0
v0 = -0.1
[[spring]]
connects = ["ground", "a"]
k = 300.0
[[spring]]
connects = ["a", "b"]
k = 150.0
[[damper]]
connects = ["a", "b"]
c = 2.0
[[force]]
on = "b"
type = "sine"
amplitude = 3.0
omega = 4.0
[ground_motion]
quantity = "acceleration"
type = "table"
units = "g"
t = [0.0, 0.5, 1.0, 1.7, 2.5, 3.0]
values = [0.0, 0.2, -0.3, 0.25, -0.1, 0.0]
"""


@functools.cache
def _tight_reference() -> np.ndarray:
    """CHAIN's relative displacement on its grid by scipy's DOP853 at rtol 1e-13, restarted at the record's kinks:
    solved once for every method compared with it (scipy's Radau at rtol 1e-12 agrees to 2e-13 and took 8 s)."""
    sc = scenario.parse(CHAIN, "chain.toml")
    model, grid = build(sc), time_grid(sc.time)
    times, values = np.array(sc.ground_motion.shape.t), np.array(sc.ground_motion.shape.values)
    M, C, K = model.M, model.C, model.K
    n = 2
    Minv = np.linalg.inv(M)

    def rhs(s, z):
        f = -M @ np.ones(n) * np.interp(s, times, values) - C @ z[n:] - K @ z[:n] + np.array([0, 3 * np.sin(4 * s)])
        return np.concatenate([z[n:], Minv @ f])

    ref = np.empty((len(grid), n))
    z = np.array([0.01, 0.0, 0.0, -0.1])
    edges = [0.0] + [s for s in times if 0 < s < 5] + [5.0]
    for lo, hi in zip(edges[:-1], edges[1:]):  # restart at the record's kinks
        keep = (grid >= lo) & (grid <= hi)
        sol = solve_ivp(rhs, (lo, hi), z, method="DOP853", rtol=1e-13, atol=1e-16, dense_output=True)
        ref[keep] = sol.sol(grid[keep])[:n].T
        z = sol.y[:, -1]
    return ref


@pytest.mark.parametrize("method", ["exact", "DOP853", "Radau", "RK45"])
def test_a_record_and_a_force_together_match_a_tight_reference(tmp_path, method):
    """Ground acceleration (piecewise linear, in g) plus a force, initial state relative: every method against an
    independent tight solve of the relative equation (scipy's DOP853)."""
    path = tmp_path / "chain.toml"
    path.write_text(CHAIN)
    sc = scenario.load(path)
    model, grid = build(sc), time_grid(sc.time)
    tight = Tolerances(rtol=1e-11, atol=1e-14)
    result = solve(model, grid, method, tight)
    times, values = np.array(sc.ground_motion.shape.t), np.array(sc.ground_motion.shape.values)
    ref = _tight_reference()
    error = np.abs(result.displacement - ref).max() / np.abs(ref).max()
    assert error <= (1e-8 if method in ("exact", "DOP853", "Radau") else 1e-6), error
    # The ground integrated from rest: its velocity is the record's integral (trapezoids are exact for it).
    from scipy.integrate import cumulative_trapezoid

    fine = np.linspace(0, 5, 50001)
    velocity = cumulative_trapezoid(np.interp(fine, times, values), fine, initial=0.0)
    np.testing.assert_allclose(result.ground.velocity, np.interp(grid, fine, velocity), atol=1e-12)


def test_a_displacement_pulse_jumps_the_relative_state_and_matches_the_absolute_solve(tmp_path, cli):
    """The bundled quarter car: absolute motion solved piecewise by scipy's DOP853 (road constant between its jumps,
    the tyre damper's impulse c du added to the wheel's velocity at each) equals smd's absolute_displacement."""
    result = cli("simulate", SCENARIOS / "quarter_car_bump.toml", "-o", tmp_path, "--no-plots")
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "quarter_car_bump.h5") as f:
        t, absolute, relative = f["time"][()], f["absolute_displacement"][()], f["displacement"][()]
        road = f["ground/displacement"][()]
        assert f["ground"].attrs["jumps"] == 2
    model = build(scenario.load(SCENARIOS / "quarter_car_bump.toml"))
    M, C, K = model.M, model.C, model.K
    ones = np.ones(2)
    Minv = np.linalg.inv(M)
    z = np.zeros(4)
    out = []
    for lo, hi, u, jump in ((0, 0.5, 0.0, 0.05), (0.5, 0.9, 0.05, -0.05), (0.9, 3.0, 0.0, 0.0)):
        keep = (t >= lo) & (t < hi) if hi < 3 else t >= lo
        sol = solve_ivp(lambda s, y, u=u: np.concatenate([y[2:], Minv @ (K @ ones * u - C @ y[2:] - K @ y[:2])]),
                        (lo, hi), z, method=REFERENCE_METHOD, rtol=1e-13, atol=1e-16, dense_output=True)
        out.append(sol.sol(t[keep])[:2].T)
        z = sol.y[:, -1].copy()
        z[2:] += Minv @ C @ ones * jump
    reference = np.concatenate(out)
    assert np.abs(absolute - reference).max() <= 1e-8 * np.abs(reference).max()
    at = np.searchsorted(t, 0.5)
    np.testing.assert_allclose(relative[at], -0.05 * ones + absolute[at], atol=1e-15)  # right limit: road up
    np.testing.assert_allclose(road, np.where((t >= 0.5) & (t < 0.9), 0.05, 0.0))


@pytest.mark.parametrize("method", ["DOP853", "Radau"])
def test_an_event_driven_run_s_sample_on_a_ground_jump_is_its_right_limit(method):
    """A yielding storey under a displacement pulse whose jumps fall on samples: the event-driven integrators' samples
    there are the right limits (the relative displacement -0.12 m at the pulse's start), as the exact solver's; they
    stored the left limit (0 m) until the row was written again after the jump."""
    text = UNFORCED_STOREY + ground_pulse("displacement", 0.12, 0.2, 0.5)
    sc, model, grid = model_of(text, "pulse.toml")
    exact = solve(model, grid, "exact", Tolerances())
    run = solve(model, grid, method, Tolerances(rtol=1e-10, atol=1e-13))
    np.testing.assert_allclose(exact.displacement[np.searchsorted(grid, 0.2)], [-0.12], atol=1e-15)
    # at rtol 1e-10 the integrators' global error (measured 1.2e-11 and 1.1e-10 of the peak), on the jumps too
    assert np.abs(run.displacement - exact.displacement).max() <= 1e-8 * np.abs(exact.displacement).max()


@pytest.mark.parametrize("method", ["exact", "DOP853"])
@pytest.mark.parametrize("amplitude, first_kind, speed", [(0.2, "impact", 0.1), (-0.2, "separation", 0.2)],
                         ids=["driven into the mass", "leaving the mass"])
def test_a_ground_jump_strikes_or_lets_go_a_mass_resting_on_its_stop(method, amplitude, first_kind, speed):
    """A mass pressed onto its stop (restitution 0.5) when the ground's velocity jumps: the stop driven into it
    strikes it (the mass leaves at 0.5 x 0.2 m/s), the stop moving away lets it go (at 0.2 m/s); either flight ends
    where an independent DOP853 solve of the free mass (x'' = -100 x - 0.5 x' - 3) comes back to the stop. Both
    kept the mass resting on the stop, unmoved."""
    sc, model, grid = model_of(RESTING_ON_A_STOP + ground_pulse("velocity", amplitude, 0.5, 0.2), "stop.toml")
    events = solve(model, grid, method, Tolerances(rtol=1e-12, atol=1e-15)).nonsmooth.events
    assert events[0][0] == 0.5 and events[0][2] == first_kind, events[:2]

    def back(t, y):
        return y[0] + 0.01
    back.terminal, back.direction = True, -1
    flight = solve_ivp(lambda t, y: [y[1], -100 * y[0] - 0.5 * y[1] - 3], (0.5, 1.5), [-0.01, speed],
                       method=REFERENCE_METHOD, rtol=1e-13, atol=1e-16, events=back)
    assert events[1][2] == "impact" and abs(events[1][0] - flight.t_events[0][0]) <= 1e-9, (events[1], flight.t_events)


@pytest.mark.parametrize("method", ["Radau", "rk4", "auto"])
def test_a_ground_displacement_expression_with_jumps_is_the_pulse_it_spells(method):
    """0.05 heaviside(t - a) - 0.05 heaviside(t - b) is the quarter car's plank: its edges are located (to
    adjacent floats, between output points here) and jump the relative state as the pulse's do. Integrators give
    the pulse's answer to rounding; auto (DOP853 for an expression, exact for the pulse) within its tolerance."""
    pulse = (SCENARIOS / "quarter_car_bump.toml").read_text().replace("t0 = 0.5", "t0 = 0.5004").replace(
        "duration = 0.4", "duration = 0.4003")
    spelled = pulse.replace('type = "pulse"\namplitude = 0.05\nt0 = 0.5004\nduration = 0.4003',
                            'type = "expression"\nexpr = "0.05 * heaviside(t - 0.5004) - 0.05 * heaviside(t - 0.9007)"')
    assert "heaviside" in spelled and "pulse" not in spelled.split("[ground_motion]")[1]
    runs = []
    for text in (pulse, spelled):
        _, model, grid = model_of(text)
        runs.append(solve(model, grid, method, Tolerances(rtol=1e-9, atol=1e-12)))
    jumps = np.array([(t, du) for t, du, _ in model.ground.jumps])
    assert np.abs(jumps - np.array([(0.5004, 0.05), (0.9007, -0.05)])).max() <= 1e-15
    peak = np.abs(runs[0].displacement).max()
    bound = 1e-12 if method != "auto" else 1e-7
    assert np.abs(runs[1].displacement - runs[0].displacement).max() <= bound * peak


def test_nonlinear_elements_see_relative_motion(tmp_path):
    """A cubic spring to a moving ground, solved by auto against a tight solve of the relative equation."""
    text = ONE_DOF.format(end=4.0, step=0.01, m=1.0, k=50.0, c=0.5, U=0.05, w=6.0).replace(
        'k = 50.0', 'k = 50.0\nlaw = "cubic"\nk3 = 4000.0')
    path = tmp_path / "duffing_base.toml"
    path.write_text(text)
    model = build(scenario.load(path))
    grid = time_grid(scenario.load(path).time)
    result = solve(model, grid, "auto", Tolerances(rtol=1e-11, atol=1e-14))
    ref = relative_motion_reference(model.M, model.C, model.K, lambda s: -0.05 * 36 * np.sin(6 * s), grid,
                                    cubic=4000.0)
    assert np.abs(result.displacement - ref).max() <= 1e-7 * np.abs(ref).max()


@pytest.mark.parametrize("shape", [
    'type = "expression"\nexpr = "0.02 * sin(6 * t) * exp(-0.3 * t)"',
    'type = "chirp"\namplitude = 0.02\nf0 = 0.5\nf1 = 2.0\nt1 = 4.0',
    'type = "fourier_square"\namplitude = 0.02\nomega = 3.0\nterms = 5',
])
def test_derived_ground_accelerations_equal_the_given_displacements_second_derivative(tmp_path, shape):
    """Expressions, chirps and Fourier series of displacement are differentiated exactly: the ground's velocity
    and acceleration against central differences of its displacement (h = 1e-4: truncation ~1e-8)."""
    text = ONE_DOF.format(end=4.0, step=0.01, m=1.0, k=50.0, c=0.5, U=0.0, w=1.0)
    text = text.split('type = "sine"')[0] + shape + "\n"
    path = tmp_path / "shape.toml"
    path.write_text(text)
    ground = build(scenario.load(path)).ground
    t = np.linspace(0.3, 3.7, 50)
    h = 1e-4
    u = ground.given.value
    np.testing.assert_allclose(ground.velocity.value(t), (u(t + h) - u(t - h)) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(ground.acceleration.value(t), (u(t + h) - 2 * u(t) + u(t - h)) / h**2, atol=2e-5)


def test_ground_velocity_table_integrates_to_its_displacement(tmp_path):
    text = ONE_DOF.format(end=3.0, step=0.01, m=1.0, k=50.0, c=0.5, U=0.0, w=1.0)
    text = text.split('quantity = "displacement"')[0] + (
        'quantity = "velocity"\ntype = "table"\nt = [0.5, 1.0, 2.0]\nvalues = [0.0, 0.2, 0.0]\n')
    path = tmp_path / "velocity.toml"
    path.write_text(text)
    sc = scenario.load(path)
    result = solve(build(sc), time_grid(sc.time), "exact", Tolerances())
    t = result.time
    velocity = np.interp(t, [0.5, 1.0, 2.0], [0.0, 0.2, 0.0])
    displacement = np.where(t < 0.5, 0.0, np.where(t < 1.0, 0.2 * (t - 0.5) ** 2, np.where(
        t < 2.0, 0.05 + 0.2 * (t - 1.0) - 0.1 * (t - 1.0) ** 2, 0.15)))
    np.testing.assert_allclose(result.ground.velocity, velocity, atol=1e-15)
    np.testing.assert_allclose(result.ground.displacement, displacement, atol=1e-14)
    np.testing.assert_allclose(result.ground.acceleration, np.where((t >= 0.5) & (t < 1.0), 0.4,
                                                                    np.where((t >= 1.0) & (t < 2.0), -0.2, 0.0)))


def test_transmissibility_sweep_matches_the_closed_form(tmp_path, cli):
    result = cli("sweep", SCENARIOS / "transmissibility_1dof.toml", "-o", tmp_path, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["input_dof"] == "ground"
    with h5py.File(tmp_path / "transmissibility_1dof_sweep.h5") as f:
        omega, amplitude = f["frequency"][()], f["amplitude"][:, :, 0]
        forces, ratio = f["force_transmissibility"][()], f["frequency_ratio"][()]
        zeta = f["zeta"][()] if "zeta" in f else np.array([0.05, 0.1, 0.2, 0.5, 1.0])
    for s, z in enumerate(zeta):
        expected = closed_form_transmissibility(ratio[s], z)
        np.testing.assert_allclose(amplitude[s], expected, rtol=1e-12)
        np.testing.assert_allclose(forces[s], ratio[s] ** 2 * expected, rtol=1e-12)
    # Every curve passes 1 at r = sqrt(2); the peaks are those of the closed form.
    for peak in data["peaks"]:
        z = zeta[peak["member"]]
        r_peak = np.sqrt(np.sqrt(1 + 8 * z**2) - 1) / (2 * z)
        assert peak["omega"] == pytest.approx(r_peak * 10, rel=1e-7)
        assert peak["amplitude"] == pytest.approx(closed_form_transmissibility(r_peak, z), rel=1e-10)


def test_a_sweep_over_mass_under_ground_motion_matches_each_simulation(tmp_path, cli):
    """Members of different mass feel different effective forces -M 1 a_g: the batched sweep must not share one."""
    text = (SCENARIOS / "transmissibility_1dof.toml").read_text().split("[sweep]")[0]
    path = tmp_path / "masses.toml"
    path.write_text(text.replace("end = 10.0", "end = 2.0") + '[sweep]\nparameter = "mass[0].m"\nvalues = [0.5, 2.0]\n')
    assert cli("sweep", path, "-o", tmp_path, "--no-plots").exit_code == 0
    with h5py.File(tmp_path / "masses_sweep.h5") as f:
        stacked = f["displacement"][()]
    for s, m in enumerate((0.5, 2.0)):
        single = tmp_path / f"m{s}.toml"
        single.write_text(text.replace("end = 10.0", "end = 2.0").replace("m = 1.0", f"m = {m}"))
        assert cli("simulate", single, "-o", tmp_path, "--no-plots").exit_code == 0
        with h5py.File(tmp_path / f"m{s}.h5") as f:
            np.testing.assert_allclose(stacked[s], f["displacement"][()], rtol=0, atol=1e-12 * np.abs(stacked).max())


def test_spectrum_of_a_scenarios_record_equals_the_records_own(tmp_path, cli):
    a = cli("spectrum", SCENARIOS / "shear_frame_record.toml", "-o", tmp_path / "a", "--no-plots", "--json")
    b = cli("spectrum", ROOT / "records" / "synthetic_20s_100hz.csv", "-o", tmp_path / "b", "--no-plots")
    assert a.exit_code == 0 and b.exit_code == 0, a.output + b.output
    with h5py.File(tmp_path / "a" / "shear_frame_record_spectrum.h5") as f, \
            h5py.File(tmp_path / "b" / "synthetic_20s_100hz_spectrum.h5") as g:
        np.testing.assert_array_equal(f["Sd"][()], g["Sd"][()])
    bad = cli("spectrum", SCENARIOS / "one_dof_harmonic.toml", "-o", tmp_path / "c")
    assert bad.exit_code == 2 and "found no [ground_motion]" in bad.stderr
    assert not (tmp_path / "c").exists()


def test_the_file_keeps_relative_absolute_and_ground_motion(tmp_path, cli):
    result = cli("simulate", SCENARIOS / "shear_frame_record.toml", "-o", tmp_path, "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)[0]
    with h5py.File(tmp_path / "shear_frame_record.h5") as f:
        N = len(f["time"])
        for name in ("displacement", "velocity", "acceleration"):
            relative, absolute = f[name][()], f[f"absolute_{name}"][()]
            assert absolute.shape == relative.shape == (N, 3)
            assert [d.label for d in f[f"absolute_{name}"].dims] == [d.label for d in f[name].dims]
            np.testing.assert_allclose(absolute, relative + f[f"ground/{name}"][()][:, None], rtol=0, atol=1e-15 *
                                       np.abs(absolute).max())
        assert f["ground"].attrs["quantity"] == "acceleration"
        assert "file_text" in f["ground"]
        peak_ground = np.abs(f["ground/acceleration"][()]).max()
    assert peak_ground == pytest.approx(0.3 * 9.80665, rel=1e-3)
    assert set(summary["peak_absolute_displacement_m"]) == {"floor1", "floor2", "roof"}
