"""Shock pulses (`type = "pulse"`): each shape against the closed-form response of a damped and an undamped
oscillator, during and after the pulse, as a force and as a ground acceleration; its edges, its compiled form and
its energy balance."""

import math

import numpy as np
import pytest
from conftest import force_block, model_of, one_dof

from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

M, K = 2.0, 800.0  # omega_n = 20 rad/s
# its start between output samples, its end a rounding past one (0.0503 + 0.0917 > 142 * 0.001)
T0, DURATION, AMPLITUDE = 0.0503, 0.0917, 30.0
SHAPES = ("rectangle", "half_sine", "haversine", "triangle")


def segments(shape: str, F: float = AMPLITUDE, t0: float = T0, D: float = DURATION):
    """The pulse as pieces [ta, tb) on which F = b + s (t - ta) + a sin(w (t - ta) + phi): its textbook form."""
    if shape == "rectangle":
        return [(t0, t0 + D, F, 0.0, 0.0, 0.0, 0.0)]
    if shape == "half_sine":  # F sin(pi tau / D)
        return [(t0, t0 + D, 0.0, 0.0, F, math.pi / D, 0.0)]
    if shape == "haversine":  # F sin^2(pi tau / D) = F/2 - F/2 cos(2 pi tau / D)
        return [(t0, t0 + D, F / 2, 0.0, F / 2, 2 * math.pi / D, -math.pi / 2)]
    return [(t0, t0 + D / 2, 0.0, 2 * F / D, 0.0, 0.0, 0.0), (t0 + D / 2, t0 + D, F, -2 * F / D, 0.0, 0.0, 0.0)]


def closed_form(m, c, k, pieces, times):
    """x(t) of m x'' + c x' + k x = F(t) from rest, F given by `pieces` and zero outside them: on each piece the
    particular solutions of a line ((b + s tau)/k - c s/k^2) and of a harmonic (Im(a e^(i theta) / (k - m w^2 +
    i c w))), plus the free vibration that matches the state at the piece's start."""
    wn = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    wd, sigma = wn * math.sqrt(1 - zeta**2), zeta * wn
    out = np.zeros_like(times)
    x0 = v0 = 0.0
    pieces = list(pieces) + [(pieces[-1][1], math.inf, 0.0, 0.0, 0.0, 0.0, 0.0)]
    for ta, tb, b, s, a, w, phi in pieces:
        X = a / complex(k - m * w * w, c * w)

        def particular(tau):
            x = (b + s * tau) / k - c * s / k**2 + (X * np.exp(1j * (w * tau + phi))).imag
            v = s / k + (1j * w * X * np.exp(1j * (w * tau + phi))).imag
            return x, v

        xp0, vp0 = particular(0.0)
        A = x0 - xp0
        B = (v0 - vp0 + sigma * A) / wd

        def total(tau):
            decay = np.exp(-sigma * tau)
            cos, sin = np.cos(wd * tau), np.sin(wd * tau)
            xp, vp = particular(tau)
            return (xp + decay * (A * cos + B * sin),
                    vp + decay * ((-sigma * A + wd * B) * cos + (-sigma * B - wd * A) * sin))

        inside = (times >= ta) & (times < tb)
        out[inside] = total(times[inside] - ta)[0]
        x0, v0 = total(tb - ta) if math.isfinite(tb) else (0.0, 0.0)
    return out


def scene(shape: str, c: float, ground: bool = False) -> str:
    """A 1-DOF at rest hit by the pulse: a force on it, or (ground) the support's acceleration -F/m."""
    text = one_dof(c, k=K, m=M, x0=0.0, end=0.6, step=0.001)
    if not ground:
        return text + force_block("pulse", shape=shape, amplitude=AMPLITUDE, t0=T0, duration=DURATION)
    return text + ("[ground_motion]\nquantity = \"acceleration\"\ntype = \"pulse\"\n"
                   f"shape = \"{shape}\"\namplitude = {-AMPLITUDE / M!r}\nt0 = {T0!r}\nduration = {DURATION!r}\n")


@pytest.mark.parametrize("c", [0.0, 4.0])
@pytest.mark.parametrize("shape", SHAPES)
def test_exact_matches_the_closed_form_during_and_after_each_pulse(shape, c):
    _, model, grid = model_of(scene(shape, c))
    result = solve(model, grid, "exact", Tolerances())
    reference = closed_form(M, c, K, segments(shape), grid)
    peak = np.abs(reference).max()
    during = (grid >= T0) & (grid < T0 + DURATION)
    assert during.sum() > 80 and (grid > T0 + DURATION).sum() > 400
    assert np.abs(result.displacement[:, 0] - reference).max() <= 1e-10 * peak
    assert np.abs(reference[grid < T0]).max() == 0.0


@pytest.mark.parametrize("shape", SHAPES)
def test_a_ground_acceleration_pulse_moves_the_mass_as_the_force_m_times_it(shape):
    """Relative motion under a support acceleration a_g is motion under the force -m a_g: the shock test."""
    _, model, grid = model_of(scene(shape, 4.0, ground=True))
    result = solve(model, grid, "exact", Tolerances())
    reference = closed_form(M, 4.0, K, segments(shape), grid)
    assert np.abs(result.displacement[:, 0] - reference).max() <= 1e-10 * np.abs(reference).max()


@pytest.mark.parametrize("method", ["DOP853", "Radau", "taylor", "ode45"])
@pytest.mark.parametrize("shape", SHAPES)
def test_integrators_restart_at_the_edges_and_agree_to_their_tolerance(shape, method):
    _, model, grid = model_of(scene(shape, 4.0))
    result = solve(model, grid, method, Tolerances(rtol=1e-10, atol=1e-13))
    reference = closed_form(M, 4.0, K, segments(shape), grid)
    assert np.abs(result.displacement[:, 0] - reference).max() <= 1e-7 * np.abs(reference).max()


@pytest.mark.parametrize("shape", SHAPES)
def test_the_signal_is_zero_outside_its_window_and_continuous_where_its_shape_is(shape):
    _, model, _ = model_of(scene(shape, 4.0))
    signal = model.signals[0]
    t = np.array([T0 - 1e-3, T0, T0 + DURATION / 4, T0 + DURATION / 2, T0 + DURATION, T0 + DURATION + 1e-3])
    expected = {"rectangle": [0, 1, 1, 1, 0, 0], "half_sine": [0, 0, math.sqrt(0.5), 1, 0, 0],
                "haversine": [0, 0, 0.5, 1, 0, 0], "triangle": [0, 0, 0.5, 1, 0, 0]}[shape]
    np.testing.assert_allclose(signal.value(t), AMPLITUDE * np.array(expected, float), rtol=1e-14, atol=1e-13)
    left = signal.value_left(np.array([T0, T0 + DURATION]))
    assert left[0] == 0.0
    assert left[1] == (AMPLITUDE if shape == "rectangle" else 0.0)  # exactly: no false jump at a smooth end
    assert set(np.round(model.breakpoints(0.0, 1.0), 12)) >= {round(T0, 12), round(T0 + DURATION, 12)}


@pytest.mark.parametrize("shape", ["half_sine", "haversine"])
def test_a_ground_displacement_pulse_has_its_exact_derivatives(shape, tmp_path):
    """A displacement half-sine's velocity jumps at its edges (pi U / D), a haversine's does not; the derived
    acceleration equals central differences of the displacement inside the window."""
    from smdcli import scenario
    from smdcli.model import build

    U = 0.01
    path = tmp_path / "ground.toml"
    path.write_text(one_dof(0.5, k=K, m=M, x0=0.0, end=0.6, step=0.001)
                    + f'[ground_motion]\nquantity = "displacement"\ntype = "pulse"\nshape = "{shape}"\n'
                      f"amplitude = {U!r}\nt0 = {T0!r}\nduration = {DURATION!r}\n")
    ground = build(scenario.load(path)).ground
    jumps = {round(t, 12): dv for t, du, dv in ground.jumps}
    if shape == "half_sine":
        w = math.pi / DURATION
        assert jumps == pytest.approx({round(T0, 12): U * w, round(T0 + DURATION, 12): U * w}, rel=1e-14)
    else:
        assert jumps == {}
    t = np.linspace(T0 + 0.005, T0 + DURATION - 0.005, 40)
    h = 1e-5
    u = ground.given.value
    np.testing.assert_allclose(ground.velocity.value(t), (u(t + h) - u(t - h)) / (2 * h), atol=1e-8 * U / h)
    np.testing.assert_allclose(ground.acceleration.value(t), (u(t + h) - 2 * u(t) + u(t - h)) / h**2,
                               atol=1e-3 * U / DURATION**2)


@pytest.mark.parametrize("shape", SHAPES)
def test_the_energy_balance_closes_to_rounding(shape, tmp_path, cli):
    import h5py

    path = tmp_path / f"{shape}.toml"
    path.write_text(scene(shape, 4.0))
    ran = cli("simulate", path, "--no-plots", "-o", tmp_path / "out", "--method", "exact")
    assert ran.exit_code == 0, ran.output
    with h5py.File(tmp_path / "out" / f"{shape}.h5") as f:
        energy = f["energy"]
        residual = np.abs(energy["residual"][()]).max()
        scale = max(np.abs(energy[name][()]).max() for name in ("kinetic", "strain", "input"))
    assert residual <= 1e-10 * scale


def test_a_pulse_shape_is_read_with_one_clear_line(tmp_path, cli):
    path = tmp_path / "bad.toml"
    path.write_text(one_dof(0.5) + force_block("pulse", shape="half_sin", amplitude=1.0, duration=0.1))
    ran = cli("simulate", path, "--no-plots", "-o", tmp_path / "out")
    assert ran.exit_code == 2
    assert "force[0].shape" in ran.stderr and "half_sine" in ran.stderr
    assert not (tmp_path / "out").exists()


def test_the_bundled_shock_test_peaks_where_the_shock_spectrum_of_the_sampled_pulse_says():
    """scenarios/shock_half_sine.toml (the exact pulse) against smd's shock response spectrum of the same pulse
    sampled at 100 kHz (records/half_sine_11ms_50g.csv): the maximax absolute acceleration at 80 Hz, Q = 10,
    agrees to the record's sampling error (O(dt^2): 1e-6 of the peak here)."""
    import smdcli
    from conftest import ROOT, bundled

    sc, model, grid = bundled("shock_half_sine")
    result = solve(model, grid, "exact", Tolerances())
    assert sc.ground_motion.shape.shape == "half_sine"
    k, c, m = model.K[0, 0], model.C[0, 0], model.M[0, 0]
    absolute = -(k * result.displacement[:, 0] + c * result.velocity[:, 0]) / m  # the mass's own acceleration
    record = smdcli.read_record(ROOT / "records" / "half_sine_11ms_50g.csv")
    fn, q = math.sqrt(k / m) / (2 * math.pi), 1 / (2 * c / (2 * math.sqrt(k * m)))
    srs = smdcli.shock_response_spectrum(record.time, record.acceleration, [fn], q=[q])
    peak = float(srs.maximax[0, 0])
    assert 1.6 * 50 * 9.80665 < peak < 1.7 * 50 * 9.80665  # the classic overshoot near 80 Hz
    # the output grid (0.1 ms) samples the peak: refine it where it is, exactly, from the run's state
    dense = solve(model, np.linspace(0.0, 0.03, 300_001), "exact", Tolerances())
    finest = np.abs(k * dense.displacement[:, 0] + c * dense.velocity[:, 0]).max() / m
    assert abs(finest - peak) <= 1e-5 * peak
    assert np.abs(absolute).max() <= finest * (1 + 1e-12)


def test_a_field_of_another_shape_is_named_as_such(tmp_path, cli):
    path = tmp_path / "sine.toml"
    path.write_text(one_dof(0.5) + force_block("sine", amplitude=1.0, omega=3.0, shape="half_sine"))
    ran = cli("simulate", path, "--no-plots", "-o", tmp_path / "out")
    assert ran.exit_code == 2
    assert 'force[0].shape: type = "sine" takes no shape (a field of type = "pulse")' in ran.stderr


@pytest.mark.parametrize("quantity", ["displacement", "velocity"])
@pytest.mark.parametrize("shape", SHAPES)
def test_a_ground_displacement_or_velocity_pulse_moves_the_mass_as_the_absolute_equation_says(shape, quantity):
    """Absolute motion x = y + u under the support's pulse: m x'' + c (x' - u') + k (x - u) = 0, integrated by
    DOP853 (rtol 1e-13) piece by piece between the pulse's edges, u from its velocity where that is what is given,
    a jump of u passing the damper's impulse c du to the mass. smd: the relative motion, its derived ground
    accelerations and state jumps, plus the ground's own motion."""
    from scipy.integrate import solve_ivp

    c, U = 4.0, 0.01
    text = one_dof(c, k=K, m=M, x0=0.0, end=0.6, step=0.001) + (
        f'[ground_motion]\nquantity = "{quantity}"\ntype = "pulse"\nshape = "{shape}"\namplitude = {U!r}\n'
        f"t0 = {T0!r}\nduration = {DURATION!r}\n")
    _, model, grid = model_of(text)
    run = solve(model, grid, "exact", Tolerances())
    given = model.ground.given
    edges = [0.0, T0, T0 + DURATION / 2, T0 + DURATION, 0.6]
    y, pieces = np.zeros(3), []  # x, x', u
    for a, b in zip(edges[:-1], edges[1:]):
        inside = lambda t, a=a, b=b: min(max(t, a), np.nextafter(b, a))  # noqa: E731  (the piece's own side)
        if quantity == "displacement":  # u itself, and its jump at a: the damper's impulse
            jump = float(given.value(a) - given.value_left(a)) if a > 0 else 0.0
            y = y + [0.0, c * jump / M, 0.0]
            u = lambda t, y, inside=inside: float(given.value(inside(t)))  # noqa: E731
            rate = lambda t, inside=inside: float(model.ground.velocity.value(inside(t))) \
                if model.ground.velocity is not None else 0.0  # noqa: E731
        else:
            u = lambda t, y: y[2]  # noqa: E731
            rate = lambda t, inside=inside: float(given.value(inside(t)))  # noqa: E731

        def flow(t, y, u=u, rate=rate):
            return [y[1], (c * (rate(t) - y[1]) + K * (u(t, y) - y[0])) / M, rate(t)]

        solution = solve_ivp(flow, (a, b), y, method="DOP853", rtol=1e-13, atol=1e-18, dense_output=True)
        pieces.append(solution.sol(grid[(grid >= a) & (grid < b)])[0])
        y = solution.sol(b)
    reference = np.concatenate(pieces)
    absolute = run.displacement[:len(reference), 0] + run.ground.displacement[:len(reference)]
    assert np.abs(absolute - reference).max() <= 1e-10 * np.abs(reference).max()
