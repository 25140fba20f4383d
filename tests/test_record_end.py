"""A recorded ground acceleration shorter than the run ends at its last sample (zero acceleration after it, the
ground moving on at the velocity it reached), with a warning naming the record's end; `hold = true` keeps its last
value instead. Before, the last sample was held without a word: a 15 s record ending at 0.02 g in a 30 s run
pushed on for 15 s more. And record units that are a known scaling of SI are converted, never "did you mean" a
unit of another magnitude. Each against the closed form of an undamped oscillator under a constant acceleration.
"""

import math

import numpy as np
import pytest

import smdcli
from smdcli.errors import ScenarioError

G = 9.80665
OMEGA = 2 * math.pi
T_END_RECORD = 15.0


def scene(tmp_path, value=0.02, units="g", extra="", stop=False):
    times = np.arange(0.0, T_END_RECORD + 1e-9, 0.01)
    np.savetxt(tmp_path / "record.csv", np.c_[times, np.full_like(times, value)], delimiter=",")
    stop_table = '[[stop]]\nconnects = ["ground", "m1"]\nmax = 0.004\nrestitution = 0.5\n' if stop else ""
    (tmp_path / "short.toml").write_text(f"""
[time]
end = 30.0
step = 0.01
[[mass]]
name = "m1"
m = 1.0
[[spring]]
connects = ["ground", "m1"]
k = {OMEGA ** 2!r}
{stop_table}
[ground_motion]
quantity = "acceleration"
type = "table"
file = "record.csv"
units = "{units}"
{extra}
""")
    return tmp_path / "short.toml"


def relative_motion(t, a, held):
    """y'' + w^2 y = -a up to the record's end (or throughout, held), free after it; from rest."""
    y = -a / OMEGA ** 2 * (1 - np.cos(OMEGA * t))
    if not held:
        yN = -a / OMEGA ** 2 * (1 - math.cos(OMEGA * T_END_RECORD))
        vN = -a / OMEGA * math.sin(OMEGA * T_END_RECORD)
        s = t[t >= T_END_RECORD] - T_END_RECORD
        y[t >= T_END_RECORD] = yN * np.cos(OMEGA * s) + vN / OMEGA * np.sin(OMEGA * s)
    return y


@pytest.mark.parametrize("method, tolerance", [("exact", 1e-12), ("Radau", 1e-8), ("DOP853", 1e-7)])
def test_a_record_ends_at_its_last_sample_with_a_warning(tmp_path, method, tolerance):
    result = smdcli.simulate(scene(tmp_path), method=method, rtol=1e-10, atol=1e-13)
    a = 0.02 * G
    expected = relative_motion(result.time, a, held=False)
    assert np.abs(result.displacement[:, 0] - expected).max() <= tolerance * np.abs(expected).max()
    # the ground: its velocity stays at a t_N after the end, its displacement grows linearly
    t = result.time
    ground_v = np.where(t < T_END_RECORD, a * t, a * T_END_RECORD)
    ground_u = np.where(t < T_END_RECORD, 0.5 * a * t ** 2,
                        0.5 * a * T_END_RECORD ** 2 + a * T_END_RECORD * (t - T_END_RECORD))
    np.testing.assert_allclose(result.ground.velocity, ground_v, rtol=0, atol=1e-12 * a * T_END_RECORD)
    np.testing.assert_allclose(result.ground.displacement, ground_u, rtol=0, atol=1e-9 * ground_u[-1])
    assert np.abs(result.ground.acceleration[t > T_END_RECORD]).max() == 0.0
    ends = [note for note in result.notes if "ends at t = 15 s" in note]
    assert len(ends) == 1 and "zero ground acceleration" in ends[0] and "hold = true" in ends[0]


def test_hold_true_keeps_the_last_value(tmp_path):
    result = smdcli.simulate(scene(tmp_path, extra="hold = true"))
    expected = relative_motion(result.time, 0.02 * G, held=True)
    assert np.abs(result.displacement[:, 0] - expected).max() <= 1e-12 * np.abs(expected).max()
    assert any("held to the end (hold = true)" in note for note in result.notes)


def test_a_nonsmooth_scene_sees_the_record_end_too(tmp_path):
    """A stop the mass rattles against while the record lasts: exact and an integrator agree, and both are free of
    the ground's push after the end (the mass's relative motion then conserves energy but for the impacts)."""
    path = scene(tmp_path, value=0.05, stop=True)
    exact = smdcli.simulate(path, method="exact")
    radau = smdcli.simulate(path, method="Radau", rtol=1e-10, atol=1e-13)
    peak = np.abs(exact.displacement).max()
    assert np.abs(exact.displacement - radau.displacement).max() <= 1e-6 * peak
    assert exact.displacement.max() <= 0.004 * (1 + 1e-12)
    work_after = np.diff(exact.energy.input[exact.time >= T_END_RECORD])
    assert np.abs(work_after).max() <= 1e-12 * np.abs(exact.energy.input).max()


@pytest.mark.parametrize("units, factor", [("cm/s^2", 0.01), ("gal", 0.01), ("Gal", 0.01), ("mm/s^2", 1e-3),
                                           ("m/s^2", 1.0), ("g", G)])
def test_record_units_that_scale_si_are_converted(tmp_path, units, factor):
    result = smdcli.simulate(scene(tmp_path, value=2.0, units=units), method="exact")
    expected = relative_motion(result.time, 2.0 * factor, held=False)
    assert np.abs(result.displacement[:, 0] - expected).max() <= 1e-12 * np.abs(expected).max()


def test_an_unknown_unit_is_refused_without_a_near_spelling_of_another_magnitude(tmp_path):
    with pytest.raises(ScenarioError) as caught:
        smdcli.simulate(scene(tmp_path, units="cm/sec2"))
    message = str(caught.value)
    assert "ground_motion.units" in message and "'cm/sec2'" in message and "cm/s^2" in message
    assert "did you mean" not in message


def test_hold_is_refused_on_anything_but_a_recorded_acceleration(tmp_path):
    (tmp_path / "s.toml").write_text("""
[time]
end = 1.0
[[mass]]
name = "m1"
m = 1.0
[[spring]]
connects = ["ground", "m1"]
k = 1.0
[ground_motion]
quantity = "acceleration"
type = "sine"
amplitude = 1.0
omega = 1.0
hold = true
""")
    with pytest.raises(ScenarioError, match="ground_motion.hold"):
        smdcli.load(tmp_path / "s.toml")


def test_a_sine_ground_acceleration_from_rest_warns_that_the_ground_drifts(tmp_path):
    """a_g = A sin(w t) from rest: the ground's velocity is A / w (1 - cos w t), its mean A / w, so the ground walks
    away: u_g(T) = A / w (T - sin(w T) / w). Records got a warning for this; other shapes did not (0.78 m in 5 s)."""
    (tmp_path / "s.toml").write_text("""
[time]
end = 5.0
step = 0.01
[[mass]]
name = "m1"
m = 1.0
[[spring]]
connects = ["ground", "m1"]
k = 100.0
[ground_motion]
quantity = "acceleration"
type = "sine"
amplitude = 2.0
omega = 5.0
""")
    result = smdcli.simulate(tmp_path / "s.toml")
    drift = 2.0 / 5.0 * (5.0 - math.sin(25.0) / 5.0)
    assert abs(result.ground.displacement[-1] - drift) <= 1e-12 * drift
    notes = [n for n in result.notes if "from the ground acceleration" in n]
    assert len(notes) == 1 and f"{drift:.4g} m" in notes[0] and 'quantity = "displacement"' in notes[0]
