"""Sensitivities of scenes that mix events with smooth nonlinear terms (analysis/mixed_sensitivity.py): Stribeck
stick-slip against central differences of an event-driven run written here; friction beside a cubic spring and
impacts beside a Bouc-Wen spring, yielding springs beside a quadratic damper, a cubic spring and friction against
central differences of smd's DOP853 runs at rtol 1e-13, under the ground's jumps too; and the fit they serve (a
Stribeck contact's forces and velocity from its response)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import smdcli
from smdcli import scenario
from smdcli.sweep.family import scenario_with

from conftest import force_block, one_dof
from test_event_sensitivity import ELASTOPLASTIC, HELD_AT_BREAKAWAY, UNFORCED_STOREY, dop853_differences, \
    ground_pulse
from test_sensitivity import REGULARIZED

STRIBECK_BELT = """
[time]
end = 3.0
step = 0.01
[[mass]]
name = "block"
m = 1.0
[[spring]]
connects = ["ground", "block"]
k = 100.0
[[damper]]
connects = ["ground", "block"]
c = 0.5
[[friction]]
connects = ["ground", "block"]
force = 2.0
static = 3.0
stribeck_velocity = 0.05
belt_velocity = 0.1
"""
STRIBECK_PATHS = {"m": "mass.block.m", "k": "spring[0].k", "c": "damper[0].c", "F": "friction[0].force",
                  "Fs": "friction[0].static", "vs": "friction[0].stribeck_velocity", "vb": "friction[0].belt_velocity"}
STRIBECK_VALUES = dict(m=1.0, k=100.0, c=0.5, F=2.0, Fs=3.0, vs=0.05, vb=0.1)


def stribeck_belt(grid, m, k, c, F, Fs, vs, vb):
    """x on the grid of a block on a spring and damper to a wall riding a belt at vb, its friction falling from Fs
    to F as exp(-(v_r / vs)^2) while it slips (v_r = x' - vb), written here with its own modes and events: DOP853 at
    rtol 1e-13 to the speed's zero (stick, or slip on the other way where the held force passes Fs) and to the held
    force's reaching Fs (slip)."""
    def held(x):  # the friction force that keeps the block moving with the belt
        return -k * x - c * vb

    t, y, mode, out = 0.0, np.array([0.0, 0.0]), -1.0, np.empty(len(grid))  # at rest, the belt sliding under it
    while t < grid[-1]:
        if mode == 0:
            def rate(_, z):
                return [vb, 0.0]

            def event(_, z):
                return abs(held(z[0])) - Fs
            event.direction = 1
        else:
            def rate(_, z, s=mode):
                return [z[1], (-k * z[0] - c * z[1] - s * (F + (Fs - F) * np.exp(-((z[1] - vb) / vs) ** 2))) / m]

            def event(_, z):
                return z[1] - vb
            event.direction = -mode
        event.terminal = True
        run = solve_ivp(rate, (t, grid[-1]), y, method="DOP853", rtol=1e-13, atol=1e-16, events=event,
                        dense_output=True)
        stop = float(run.t_events[0][0]) if run.status == 1 else float(grid[-1])
        rows = (grid >= t) & ((grid < stop) if run.status == 1 else (grid <= stop))
        out[rows] = run.sol(grid[rows])[0]
        y, t = run.sol(stop), stop
        if run.status == 1:
            if mode != 0:
                y = np.array([y[0], vb])
            mode = 0.0 if mode != 0 and abs(held(y[0])) <= Fs else float(np.sign(held(y[0])))
    return out


def test_stribeck_stick_slip_matches_differences_of_an_event_driven_run_written_here():
    """Every number of the scene (the mass, spring, damper, both friction forces, the Stribeck velocity and the
    belt's speed) over three stick-slip cycles: within 1e-7 of each sensitivity's largest (measured 2e-9 to 1.2e-8)
    of five-point central differences of the run above at 1e-4 of the value, and within what smd states."""
    sc = scenario.parse(STRIBECK_BELT, "stribeck.toml")
    s = smdcli.sensitivity(sc, list(STRIBECK_PATHS.values()))
    assert s.notes == () and "event to event" in s.method
    x = stribeck_belt(s.time, **STRIBECK_VALUES)
    assert np.abs(s.displacement[:, 0] - x).max() <= 1e-8 * np.abs(x).max()
    for i, (key, path) in enumerate(STRIBECK_PATHS.items()):
        h = 1e-4 * STRIBECK_VALUES[key]
        runs = {o: stribeck_belt(s.time, **{**STRIBECK_VALUES, key: STRIBECK_VALUES[key] + o * h})
                for o in (-2, -1, 1, 2)}
        want = (8 * (runs[1] - runs[-1]) - (runs[2] - runs[-2])) / (12 * h)
        error = np.abs(s.d_displacement[i, :, 0] - want).max() / np.abs(want).max()
        assert error <= 1e-7, (path, error)
        assert error <= 10 * s.accuracy["d_displacement"][i], (path, error)


CUBIC_FRICTION = """
[time]
end = 4.0
step = 0.01
[[mass]]
name = "a"
m = 1.0
[[mass]]
name = "b"
m = 0.5
[[spring]]
connects = ["ground", "a"]
law = "cubic"
k = 40.0
k3 = 2000.0
[[spring]]
connects = ["a", "b"]
k = 60.0
[[damper]]
connects = ["ground", "a"]
c = 0.4
[[friction]]
connects = ["ground", "b"]
force = 1.0
static = 1.4
[[force]]
on = "a"
type = "sine"
amplitude = 6.0
omega = 7.0
"""

BOUC_WEN_STOP = """
[time]
end = 2.0
step = 0.005
[[mass]]
name = "m"
m = 1.0
[[spring]]
connects = ["ground", "m"]
law = "bouc_wen"
k = 400.0
alpha = 0.3
A = 1.0
beta = 30.0
gamma = 10.0
n = 1.5
[[damper]]
connects = ["ground", "m"]
c = 1.0
[[stop]]
connects = ["ground", "m"]
max = 0.03
restitution = 0.7
[[force]]
on = "m"
type = "sine"
amplitude = 15.0
omega = 9.0
"""


CUBIC_BESIDE = '[[spring]]\nconnects = ["ground", "m1"]\nlaw = "cubic"\nk = 50.0\nk3 = 2.0e4\n'

STRIBECK_CHAIN = """
[time]
end = 1.0
step = 0.01
[[mass]]
name = "m0"
m = 1.0
[[mass]]
name = "m1"
m = 1.0
[[mass]]
name = "m2"
m = 1.0
[[spring]]
connects = ["ground", "m0"]
k = 50.0
[[spring]]
connects = ["m0", "m1"]
k = 50.0
[[spring]]
connects = ["m1", "m2"]
k = 50.0
[[friction]]
connects = ["ground", "m2"]
force = 0.5
static = 0.65
stribeck_velocity = 0.02
[[force]]
on = "m2"
type = "sine"
amplitude = 1.0
omega = 2.0
"""


@pytest.mark.parametrize("text, paths", [
    # Coulomb stick-slip of a mass behind a hardening spring: 10 events (measured 7.6e-10 to 4.4e-8)
    (CUBIC_FRICTION, ["friction[0].force", "friction[0].static", "spring[0].k3", "mass.b.m"]),
    # five impacts on a stop beside a Bouc-Wen spring, its hysteresis crossing its kinks (8.9e-9 to 2.7e-8)
    (BOUC_WEN_STOP, ["stop[0].restitution", "stop[0].max", "spring[0].beta"]),
    # an elastoplastic spring beside a quadratic damper: its plastic deformation's sensitivity set at each unloading
    # (measured 3.4e-10 to 3.0e-9)
    (ELASTOPLASTIC.replace("c = 1.0", 'c = 1.0\nlaw = "quadratic"'), ["spring[0].k", "spring[0].fy", "damper[0].c"]),
    # a bilinear spring (its hardening kept in K) beside a cubic one (6.8e-9 to 1.2e-8)
    (ELASTOPLASTIC.replace('law = "elastoplastic"', 'law = "bilinear"\nhardening = 0.1').replace(
        "end = 1.2", "end = 2.0") + CUBIC_BESIDE,
     ["spring[0].k", "spring[0].fy", "spring[0].hardening", "spring[1].k3"]),
    # yielding, a cubic spring and a friction contact on one mass: where the spring unloads the mass stops, and the
    # contact turns at the same instant (one event of two elements; 1.3e-9 to 4.1e-9)
    (ELASTOPLASTIC.replace("end = 1.2", "end = 2.0") + CUBIC_BESIDE +
     '[[friction]]\nconnects = ["ground", "m1"]\nforce = 5.0\nstatic = 6.0\n',
     ["spring[0].k", "spring[0].fy", "friction[0].force", "spring[1].k3"]),
    # a Stribeck contact breaking away at the end of a chain still at rest (rounding's 1e-17 m): the sensitivity
    # kernel's first step after it was 1e-16 s (0.01 |y| / |y'| alone) and failed there
    (STRIBECK_CHAIN, ["force[0].amplitude", "friction[0].static", "force[0].omega"]),
], ids=["friction beside a cubic spring", "impacts beside a Bouc-Wen spring", "yielding beside a quadratic damper",
        "bilinear beside a cubic spring", "yielding, cubic and friction", "a Stribeck contact breaking away"])
def test_events_beside_smooth_terms_match_differences_of_dop853(text, paths):
    """Against five-point central differences of smd's DOP853 runs at rtol 1e-13, events located on its interpolant
    (the forward integrator, not the sensitivity equations), at 1e-4 of each value: within 1e-7 of the largest."""
    sc = scenario.parse(text, "mixed.toml")
    s = smdcli.sensitivity(sc, paths)
    assert s.notes == () and "event to event" in s.method
    want = dop853_differences(sc, s, paths)
    for i, path in enumerate(paths):
        error = np.abs(s.d_displacement[i] - want[path]).max() / np.abs(want[path]).max()
        assert error <= 1e-7, (path, error)


def test_the_python_integration_agrees_with_the_compiled_kernel(monkeypatch):
    """The second way (scipy's DOP853 from Python, J s a central difference along s) against the compiled kernel on
    each mode's arrays: every quantity within both runs' stated errors; the peaks' derivatives against central
    differences of the peaks smd simulate locates in DOP853 runs at rtol 1e-13."""
    import smdcli.analysis.smooth_sensitivity as smooth
    from smdcli.solvers.peaks import result_peaks

    sc = scenario.parse(CUBIC_FRICTION, "mixed.toml")
    paths = ["friction[0].force", "spring[0].k3", "mass.b.m"]
    s = smdcli.sensitivity(sc, paths)
    assert "compiled DOP853" in s.method
    for i, path in enumerate(paths):
        h = 1e-4 * s.value[i]
        peaks = {o: result_peaks(smdcli.simulate(scenario_with(sc, {path: s.value[i] + o * h}), method="DOP853",
                                                 rtol=1e-13, atol=1e-18)) for o in (-2, -1, 1, 2)}
        want = (8 * (peaks[1] - peaks[-1]) - (peaks[2] - peaks[-2])) / (12 * h)
        assert np.abs(s.d_peak_displacement[i] - want).max() <= 1e-7 * np.abs(want).max(), path
    monkeypatch.setattr(smooth, "COMPILED", False)
    python = smdcli.sensitivity(sc, paths)
    assert "in Python" in python.method
    for quantity in ("d_displacement", "d_velocity", "d_acceleration"):
        a, b = getattr(s, quantity), getattr(python, quantity)
        allowed = (s.accuracy[quantity] + python.accuracy[quantity]) * np.abs(b).max(axis=(1, 2))
        assert np.all(np.abs(a - b).max(axis=(1, 2)) <= allowed), quantity


def test_a_yielding_spring_s_carried_plastic_deformation_is_the_python_integration_s_too(monkeypatch):
    """The plastic deformation's sensitivities enter the modes at the stencil's points on both ways: the compiled
    kernel's arrays of the moved states, and the Python right-hand side's: yielding, a cubic spring and friction on
    one mass, within both runs' stated errors (measured 1.1e-9 to 7.8e-9 of the largest)."""
    import smdcli.analysis.smooth_sensitivity as smooth

    text = ELASTOPLASTIC.replace("end = 1.2", "end = 1.0") + CUBIC_BESIDE + \
        '[[friction]]\nconnects = ["ground", "m1"]\nforce = 5.0\nstatic = 6.0\n'
    sc = scenario.parse(text, "mixed.toml")
    paths = ["spring[0].k", "spring[0].fy", "friction[0].force"]
    compiled = smdcli.sensitivity(sc, paths)
    monkeypatch.setattr(smooth, "COMPILED", False)
    python = smdcli.sensitivity(sc, paths)
    assert "in Python" in python.method and python.notes == compiled.notes == ()
    for quantity in ("d_displacement", "d_velocity", "d_acceleration"):
        a, b = getattr(compiled, quantity), getattr(python, quantity)
        allowed = (compiled.accuracy[quantity] + python.accuracy[quantity]) * np.abs(b).max(axis=(1, 2))
        assert np.all(np.abs(a - b).max(axis=(1, 2)) <= allowed), quantity


BOUC_WEN_FRICTION = one_dof(1.6, k=400.0, x0=0.05, end=1.0, step=0.01).replace(
    "k = 400.0", 'k = 400.0\nlaw = "bouc_wen"\nalpha = 0.5\nbeta = 20.0\ngamma = 20.0\nn = 1.0') + \
    '[[friction]]\nconnects = ["ground", "m"]\nforce = 3.0\nstatic = 4.0\n' + \
    force_block("sine", amplitude=8.0, omega=14.0)


def test_a_bouc_wen_spring_s_and_a_contact_s_forces_beside_each_other_are_differentiated_and_fitted():
    """The load cell of a Bouc-Wen spring beside a stick-slip contact (events beside smooth terms): each element's
    force (the contact's while stuck, its constraint's) and its derivatives in k, beta and the contact's force,
    differenced at the stencil's points with the state moved by its sensitivities, against DOP853's differences:
    within 1e-7 of each largest (measured 1.0e-10 to 2.7e-8); and the spring's k and beta fitted to its force and
    the displacement from 30 % off, to 1e-6."""
    from smdcli.analysis.fit import fit, make_test
    from smdcli.analysis.fit_data import Measured

    sc = scenario.parse(BOUC_WEN_FRICTION, "cell.toml")
    paths = ["spring[0].k", "spring[0].beta", "friction[0].force"]
    s = smdcli.sensitivity(sc, paths)
    assert s.notes == ()
    for element in ("spring[0]", "friction[0]"):
        tension, derived = s.element_tension(element)
        for i, path in enumerate(paths):
            h = 1e-4 * abs(s.value[i])
            runs = {o: smdcli.simulate(scenario_with(sc, {path: s.value[i] + o * h}), method="DOP853", rtol=1e-13,
                                       atol=1e-18).elements.tension(element) for o in (-2, -1, 1, 2)}
            want = (8 * (runs[1] - runs[-1]) - (runs[2] - runs[-2])) / (12 * h)
            assert np.abs(derived[i] - want).max() <= 1e-7 * np.abs(want).max(), (element, path)
    truth = smdcli.simulate(sc, method="DOP853", rtol=1e-13, atol=1e-18)
    data = Measured("cell", truth.time[1:], {"spring[0].force": truth.elements.tension("spring[0]")[1:],
                                             "m.displacement": truth.displacement[1:, 0]}, {})
    start = scenario_with(sc, {"spring[0].k": 520.0, "spring[0].beta": 14.0})
    run = fit([make_test(start, data, None, None)], ["spring[0].k", "spring[0].beta"])
    assert run.converged, run.message
    assert np.abs(run.estimate / [400.0, 20.0] - 1).max() <= 1e-6


BOUC_WEN_SLIDING = BOUC_WEN_FRICTION.split("[[force]]")[0]  # released at 0.05 m: it slides from the start


@pytest.mark.parametrize("text, paths", [
    # an elastoplastic storey beside a quadratic damper yields through each jump of a 0.12 m displacement pulse: its
    # plastic deformation's sensitivity set by the law's own jump at the moved point (measured 7.2e-10 to 4.1e-8,
    # the damper's c the largest)
    (UNFORCED_STOREY.replace("c = 1.0", 'c = 1.0\nlaw = "quadratic"') + ground_pulse("displacement", 0.12, 0.2, 0.5),
     ["spring[0].k", "spring[0].fy", "damper[0].c", "ground_motion.amplitude"]),
    # and a velocity pulse: the amplitude's and the mass's derivatives of the jump (5.0e-10 to 8.6e-10)
    (UNFORCED_STOREY.replace("c = 1.0", 'c = 1.0\nlaw = "quadratic"') + ground_pulse("velocity", 1.6, 0.2, 0.3),
     ["spring[0].k", "spring[0].fy", "ground_motion.amplitude", "mass.m1.m"]),
    # a Bouc-Wen spring beside a contact that slips through both jumps of a velocity pulse (1.0e-11 to 6.5e-11)
    (BOUC_WEN_SLIDING + ground_pulse("velocity", 0.1, 0.05, 0.1),
     ["spring[0].k", "spring[0].beta", "friction[0].force", "ground_motion.amplitude"]),
    # and one stuck by 0.3 s, set slipping by the pulse: the contact's mode decided at the moved state (1.5e-10 to
    # 1.6e-9)
    (BOUC_WEN_SLIDING + ground_pulse("velocity", 0.3, 0.3, 0.1),
     ["spring[0].k", "spring[0].beta", "friction[0].force", "ground_motion.amplitude"]),
], ids=["yielding through a displacement pulse", "yielding under a velocity pulse", "sliding under a velocity pulse",
        "stuck, then set slipping by a velocity pulse"])
def test_the_ground_s_jumps_beside_smooth_terms_match_differences_of_dop853(text, paths):
    """The relative state jumps at the pulse's ends, and its sensitivities by each parameter's derivative of the
    jump: against DOP853's differences away from the events and jumps, within 1e-7 of each largest."""
    sc = scenario.parse(text, "pulse.toml")
    s = smdcli.sensitivity(sc, paths)
    assert s.notes == () and "event to event" in s.method
    tight = smdcli.simulate(sc, method="DOP853", rtol=1e-11, atol=1e-15).displacement  # right limits on the jumps
    assert np.abs(s.displacement - tight).max() <= 1e-7 * np.abs(tight).max()
    want = dop853_differences(sc, s, paths)
    breaks = np.array([*s.event_times, *(t for t, _, _ in s.model.jumps)])  # the differences' slopes jump there
    keep = np.abs(s.time[:, None] - breaks[None]).min(axis=1) > 1e-3
    assert keep.mean() > 0.8
    for i, path in enumerate(paths):
        error = np.abs(s.d_displacement[i][keep] - want[path][keep]).max() / np.abs(want[path]).max()
        assert error <= 1e-7, (path, error)


def test_a_stop_the_motion_comes_within_rounding_of_has_no_derivative_from_there():
    """A stop set 3e-10 of the peak beyond where the mass turns (the peak located by a run without it): untouched,
    but a change of the parameters that small strikes it, so from the turn on the response has no derivative: nan
    and a note saying where, not a number."""
    free = scenario.parse(BOUC_WEN_STOP.replace("max = 0.03", "max = 1.0"), "free.toml")
    s = smdcli.sensitivity(free, ["spring[0].k"])
    top = int(np.argmax(s.peak_displacement))
    assert s.notes == ()
    touching = BOUC_WEN_STOP.replace("max = 0.03", f"max = {float(s.peak_displacement[top]) * (1 + 3e-10)!r}")
    near = smdcli.sensitivity(scenario.parse(touching, "graze.toml"), ["spring[0].k"])
    assert len(near.notes) == 1 and "without reaching it: a graze" in near.notes[0], near.notes
    when = float(near.notes[0].split("from t = ")[1].split(" s")[0])
    assert abs(when - float(s.peak_time[top])) <= 1e-6
    assert np.isnan(near.d_displacement[0][near.time >= when]).all()
    assert np.isfinite(near.d_displacement[0][near.time < when]).all()


def test_a_stribeck_contact_s_forces_and_velocity_are_recovered_from_a_start_30_percent_off():
    """Noise-free response of the Stribeck stick-slip block (an smd DOP853 run at rtol 1e-13): the kinetic and
    breakaway forces and the Stribeck velocity from 0.7, 1.3 and 0.7 times their values, to 1e-6 (measured 8e-10),
    in fewer than 50 solves, the Jacobian from the event-to-event sensitivities."""
    from smdcli.analysis.fit import fit, make_test
    from smdcli.analysis.fit_data import Measured

    sc = scenario.parse(STRIBECK_BELT, "stribeck.toml")
    result = smdcli.simulate(sc, method="DOP853", rtol=1e-13, atol=1e-16)
    data = Measured("synthetic", result.time[1:], {"block.displacement": result.displacement[1:, 0]}, {})
    truth = {"friction[0].force": 2.0, "friction[0].static": 3.0, "friction[0].stribeck_velocity": 0.05}
    paths, values = list(truth), np.array(list(truth.values()))
    run = fit([make_test(scenario_with(sc, dict(zip(paths, values * [0.7, 1.3, 0.7]))), data, None, None)], paths)
    assert run.converged, run.message
    assert np.abs(run.estimate / values - 1).max() <= 1e-6
    assert run.solves < 50


def test_a_stribeck_contact_held_at_its_breakaway_force_has_no_derivative_in_what_moves_it_off():
    """x0 = -0.02 holds a Stribeck contact at its breakaway (k x0 = static) as the force grows: it slips at once,
    where a softer spring holds it a while, so the derivatives in k and x0 differ on either side: nan, a note each.
    The mass does not move the held force: its derivative is given."""
    text = HELD_AT_BREAKAWAY.replace("X0", "-0.02").replace("static = 1.0", "static = 1.0\nstribeck_velocity = 0.05")
    paths = ["spring[0].k", "mass.m0.m", "mass.m0.x0"]
    s = smdcli.sensitivity(scenario.parse(text, "held.toml"), paths)
    assert "event to event" in s.method
    assert np.isnan(s.d_displacement[[0, 2]]).all() and np.isfinite(s.d_displacement[1]).all()
    assert [note.split(" (")[0] for note in s.notes] == [f"the response has no derivative in {path}"
                                                         for path in (paths[0], paths[2])]


# test_sensitivity's belt scene, its first spring yielding, its friction's regularization 1e-5 m/s
STIFF_BESIDE_YIELD = REGULARIZED.replace('connects = ["ground", "m1"]\nk = 100.0',
                                         'connects = ["ground", "m1"]\nlaw = "elastoplastic"\nk = 100.0\nfy = 0.5') \
    .replace("regularization = 1e-3", "regularization = 1e-5").replace("end = 3.0", "end = 1.0")


def test_a_stiff_piece_between_events_is_taken_by_radau_and_agrees_with_dop853(monkeypatch):
    """A yielding storey beside a belt's tanh friction of r = 1e-5 m/s (F / (m r) = 1.6e5 /s): between the spring's
    events the pieces are stiff, Hairer's test hands them to Radau IIA, and the method says so; k, fy and the
    friction's force agree with DOP853 alone on every piece within both runs' stated accuracies (measured 6e-11 to
    1.9e-10 of each largest, stated 1e-7)."""
    from smdcli.solvers import sensitivity_run

    assert 'law = "elastoplastic"' in STIFF_BESIDE_YIELD and "regularization = 1e-5" in STIFF_BESIDE_YIELD
    sc = scenario.parse(STIFF_BESIDE_YIELD, "stiff_beside_yield.toml")
    paths = ["spring[0].k", "spring[0].fy", "friction[0].force"]
    chosen = smdcli.sensitivity(sc, paths)
    assert "Radau IIA 5 where a piece is stiff" in chosen.method
    from smdcli.commands.sensitivity import format_sensitivity, sensitivity_summary

    assert "from event to event, compiled Radau IIA where a piece is stiff, DOP853 elsewhere)" in \
        format_sensitivity(sensitivity_summary(chosen)).splitlines()[0]
    monkeypatch.setattr(sensitivity_run, "KERNEL", "explicit")
    alone = smdcli.sensitivity(sc, paths)
    assert "compiled DOP853 (J analytic)" in alone.method
    for quantity in ("d_displacement", "d_velocity"):
        a, b = getattr(chosen, quantity), getattr(alone, quantity)
        largest = np.abs(b).max(axis=(1, 2))
        assert np.all(largest > 0)
        allowed = (chosen.accuracy[quantity] + alone.accuracy[quantity]) * largest
        assert np.all(np.abs(a - b).max(axis=(1, 2)) <= allowed), quantity
