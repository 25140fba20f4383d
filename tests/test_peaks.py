"""Peaks in the summary and --json are located between samples (solvers.peaks: the quintic Hermite of x, v and a
on the intervals beside each sample maximum), not read off the samples; against the same scene solved exactly on
an output grid 50 times finer, whose sample maxima bracket the true peaks within |x''| (h / 50)^2 / 8."""

import json

import numpy as np
import pytest
from conftest import SCENARIOS

import smdcli


def finer(path, tmp_path, factor=50):
    import tomllib

    import tomli_w

    doc = tomllib.loads(path.read_text())
    doc["time"].pop("points", None)
    step = doc["time"].get("step") or (doc["time"]["end"] - doc["time"].get("start", 0.0)) / 1000
    doc["time"]["step"] = step / factor
    text = tomli_w.dumps(doc).replace('"../records/', f'"{SCENARIOS.parent / "records"}/')
    fine = tmp_path / f"fine_{path.name}"
    fine.write_text(text)
    return fine


@pytest.mark.parametrize("stem, located_within", [("three_dof_forced", 1e-6), ("shear_frame_record", 1e-6),
                                                  ("one_dof_square_wave", 1e-9), ("two_dof_forced", 1e-9)])
def test_summary_peaks_are_located_between_samples(stem, located_within, tmp_path, cli):
    """three_dof_forced's m1 carries F1 = 20 sin(120 t): at the 0.01 s output step w h = 1.2 for that part, where the
    quintic is good to about 1e-6 of the peak (sample maximum 3.8e-4 short); the slower scenes to 1e-9."""
    ran = cli("simulate", SCENARIOS / f"{stem}.toml", "-o", tmp_path, "--no-plots", "--json")
    assert ran.exit_code == 0, ran.output
    peaks = json.loads(ran.stdout)[0]["peak_displacement_m"]
    coarse = smdcli.simulate(SCENARIOS / f"{stem}.toml")
    fine = smdcli.simulate(finer(SCENARIOS / f"{stem}.toml", tmp_path))
    # the true peak lies between the fine grid's sample maximum and that plus |x''| h^2 / 8 (a sample is at most
    # half a step from the peak, where the slope is zero)
    low = np.abs(fine.displacement).max(axis=0)
    h = float(fine.time[1] - fine.time[0])
    high = low + np.abs(fine.acceleration).max(axis=0) * h * h / 8
    sampled = np.abs(coarse.displacement).max(axis=0)
    for j, dof in enumerate(coarse.dofs):
        assert peaks[dof] >= sampled[j]  # never below what the samples show
        assert low[j] * (1 - located_within) <= peaks[dof] <= high[j] * (1 + located_within), (dof, peaks[dof],
                                                                                              low[j], high[j])
    assert np.any(np.abs(np.array(list(peaks.values())) - sampled) > 0)  # something was located between samples


def test_a_coarse_grid_or_an_event_keeps_the_sample():
    from smdcli.solvers.peaks import located_peaks

    w = 7.3
    t = np.arange(0.0, 3.0, 0.5) + 0.0037  # w h = 3.7: no interpolant to trust
    x, v, a = np.cos(w * t)[:, None], -w * np.sin(w * t)[:, None], -w * w * np.cos(w * t)[:, None]
    assert located_peaks(t, x, v, a)[0] == np.abs(x).max()
    t = np.arange(0.0, 3.0, 0.01) + 0.0037
    x, v, a = np.cos(w * t)[:, None], -w * np.sin(w * t)[:, None], -w * w * np.cos(w * t)[:, None]
    assert abs(located_peaks(t, x, v, a)[0] - 1.0) < 1e-12
    assert located_peaks(t, x, v, a, events=t)[0] == np.abs(x).max()  # every interval holds an event


BOUNCING_ON_A_STOP = """
[time]
end = 1.0
step = 0.01
[[mass]]
name = "m"
m = 1.0
[[spring]]
connects = ["ground", "m"]
k = 1000.0
[[force]]
on = "m"
type = "constant"
amplitude = 7.0
[[stop]]
connects = ["ground", "m"]
max = 0.004
restitution = 1.0
"""


@pytest.mark.parametrize("method", ["exact", "DOP853", "Radau"])
def test_a_peak_at_an_event_is_the_event_state(method, tmp_path, cli):
    """A mass pushed onto a stop at 0.004 m that rebounds elastically: its peak is the stop, reached only at the
    impacts, between samples (the samples' largest was 0.0039338 m). The events' located states join the
    candidates; the stop is never passed, so nothing above it is reported either."""
    scene = tmp_path / "bounce.toml"
    scene.write_text(BOUNCING_ON_A_STOP)
    result = cli("simulate", scene, "--method", method, "-o", tmp_path / "out", "--json")
    assert result.exit_code == 0, result.output
    peak = json.loads(result.stdout)[0]["peak_displacement_m"]["m"]
    run = smdcli.simulate(scene, method=method)
    assert np.abs(run.displacement).max() < 0.004 - 1e-5  # the samples miss it
    assert abs(peak - 0.004) <= 1e-12


def test_sweep_peaks_are_located_between_samples(tmp_path):
    """A sweep's peak_displacement metric is located between the samples as simulate's summary is: each member
    against its own scene solved exactly on a grid 50 times finer (its sample maxima within |x''| (h / 50)^2 / 8
    below the true peak)."""
    import tomllib

    import tomli_w

    from smdcli import scenario
    from smdcli.sweep import build_family, metrics, read_spec, set_parameter, solve_family

    text = (SCENARIOS / "one_dof_underdamped.toml").read_text()
    doc = tomllib.loads(text)
    doc["time"].pop("points", None)
    doc["time"]["step"] = 0.05
    doc["mass"][0].update(x0=0.0, v0=1.0)  # the peak inside the run, not the start
    sc = scenario.parse(tomli_w.dumps(doc), "coarse.toml")
    family = build_family(sc, read_spec(sc, {"parameter": ("spring[0].k",), "values": ("20, 45, 80",)}))
    result = solve_family(family)
    found = metrics(family, result)["peak_displacement"][:, 0]
    gained = []
    for s, k in enumerate(family.values[:, 0]):
        member = tomllib.loads(tomli_w.dumps(doc))
        set_parameter(member, "spring[0].k", float(k))
        member["time"]["step"] = 0.05 / 50
        fine = tmp_path / f"fine{s}.toml"
        fine.write_text(tomli_w.dumps(member))
        run = smdcli.simulate(fine)
        true_low = np.abs(run.displacement[:, 0]).max()
        slack = np.abs(run.acceleration[:, 0]).max() * (0.05 / 50) ** 2 / 8
        assert true_low - 1e-12 <= found[s] <= true_low + slack + 1e-12, (s, found[s], true_low, slack)
        gained.append(found[s] - np.abs(result.displacement[s, :, 0]).max())
    assert max(gained) > 1e-4 * found.max()  # the samples alone were short


def test_a_nonsmooth_sweep_member_peaks_at_its_events(tmp_path):
    """Members of a scene with a stop are solved one by one and bring their own located peaks, at their events
    too: every member rebounding off the 0.004 m stop peaks at 0.004 (its samples at 0.0039 at most)."""
    from smdcli import scenario
    from smdcli.sweep import build_family, metrics, read_spec, solve_family

    sc = scenario.parse(BOUNCING_ON_A_STOP, str(tmp_path / "bounce.toml"))
    family = build_family(sc, read_spec(sc, {"parameter": ("spring[0].k",), "values": ("800, 1000, 1300",)}))
    result = solve_family(family)
    found = metrics(family, result)["peak_displacement"][:, 0]
    assert np.abs(result.displacement[:, :, 0]).max() < 0.004 - 1e-5
    np.testing.assert_allclose(found, 0.004, rtol=0, atol=1e-12)


def test_histories_at_rest_cost_no_located_intervals(monkeypatch):
    """A 10,000-DOF run where a wave has reached a few DOFs: the others' samples are all zero, a plateau with no
    peak between samples. Only the moving DOFs' maxima are located (every sample of a zero row was a candidate: 31 s
    of a 7 s run), and each still gains its between-sample peak: sin(w t) sampled off its crest reads 1."""
    from smdcli.solvers import peaks as peaks_module

    located = []
    original = peaks_module._interval_peaks

    def counting(*ends):
        located.append(len(ends[0]))
        return original(*ends)

    monkeypatch.setattr(peaks_module, "_interval_peaks", counting)
    time = np.linspace(0.0, 10.0, 201)
    w = 2.0 * np.pi * 0.37  # crests between samples, 54 samples a period
    rows = 10_000
    x, v, a = (np.zeros((rows, len(time))) for _ in range(3))
    x[0], v[0], a[0] = np.sin(w * time), w * np.cos(w * time), -w * w * np.sin(w * time)
    found = peaks_module.row_peaks(time, x, v, a)
    assert found[0] == pytest.approx(1.0, abs=1e-8) and np.abs(x[0]).max() < 1 - 1e-4  # quintic: O(h^6)
    assert not found[1:].any()
    assert sum(located) <= 2 * 8 + 2  # either side of each of |sin|'s 8 crests in 3.7 periods (and an end)


def test_a_run_s_largest_peaks_in_time_are_each_located():
    """local_peaks, the pieces of a largest-peak objective: the 8 largest local maxima of |x| of a damped free
    vibration x = exp(-s t) cos(w t), sampled at w h = 0.04, against their closed form (the start, then
    t_k = (k pi - atan(s / w)) / w), to 1e-10 in value and 1e-7 s in time."""
    from smdcli.solvers.peaks import local_peaks

    s, w = 0.1, 2.0
    t = np.arange(0.0, 20.0 + 1e-9, 0.02)
    decay, c, d = np.exp(-s * t), np.cos(w * t), np.sin(w * t)
    x = decay * c
    v = -decay * (s * c + w * d)
    a = decay * ((s * s - w * w) * c + 2 * s * w * d)
    values, times = local_peaks(t, x, v, a, count=8)
    t_k = np.concatenate([[0.0], (np.arange(1, 8) * np.pi - np.arctan(s / w)) / w])
    np.testing.assert_allclose(times, t_k, atol=1e-7)
    np.testing.assert_allclose(values, np.abs(np.exp(-s * t_k) * np.cos(w * t_k)), rtol=1e-10)
