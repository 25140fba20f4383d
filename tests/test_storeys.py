"""Storey measures ([building] storey_heights): drifts, drift ratios and shears of a shear building's run with their
located peaks and residual drifts, against an independent DOP853 run and the storeys' own element laws; written to
/storeys and printed; a sweep's storey metrics equal each member's simulation."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

import smdcli

BUILDING = """
[time]
end = 3.0
step = 0.02
[[mass]]
name = "floor1"
m = 2.0e4
[[mass]]
name = "floor2"
m = 2.0e4
[[mass]]
name = "roof"
m = 1.5e4
[[mass]]
name = "tmd"
m = 1.0e3
[[spring]]
connects = ["ground", "floor1"]
k = 3.0e7
[[spring]]
connects = ["floor1", "floor2"]
k = 2.5e7
[[spring]]
connects = ["floor2", "roof"]
k = 2.0e7
[[spring]]
connects = ["roof", "tmd"]
k = 5.0e5
[[damper]]
connects = ["ground", "floor1"]
c = 6.0e4
[[damper]]
connects = ["floor1", "floor2"]
c = 5.0e4
[[damper]]
connects = ["floor2", "roof"]
c = 4.0e4
[[damper]]
connects = ["roof", "tmd"]
c = 3.0e3
[ground_motion]
quantity = "acceleration"
type = "sine"
units = "g"
amplitude = 0.25
omega = 15.0
[building]
storey_heights = [4.0, 3.5, 3.5]
masses = ["floor1", "floor2", "roof"]
"""
K = np.array([3.0e7, 2.5e7, 2.0e7])
C = np.array([6.0e4, 5.0e4, 4.0e4])
HEIGHTS = np.array([4.0, 3.5, 3.5])


def located(fine_time, values):
    """The largest |values| of a finely sampled history, refined by the parabola through its neighbours."""
    y = np.abs(values)
    k = int(np.argmax(y[1:-1])) + 1
    left, middle, right = y[k - 1:k + 2]
    return middle + (right - left) ** 2 / (8 * (2 * middle - left - right)), fine_time[k]


def test_storey_drifts_shears_and_their_located_peaks(tmp_path):
    """Drift = the floor less the one below (the TMD outside the chain), ratio over the height, shear = the storey's
    spring and damper tensions (k d + c d'), all to rounding of the run's own displacements; each peak located
    between samples against DOP853 at rtol 1e-12 sampled every 1e-4 s (a parabola through its top), to 1e-8
    (measured 2.6e-9 to 4.8e-9 for drifts, 7.6e-10 to 3e-9 for shears; the largest samples at 0.02 s are 1e-3 to
    1.9e-3 short of the drifts); the residual drift the last sample's."""
    path, fine = tmp_path / "building.toml", tmp_path / "fine.toml"
    path.write_text(BUILDING)
    fine.write_text(BUILDING.replace("step = 0.02", "step = 0.0001"))
    run = smdcli.simulate(path)
    s = run.storeys
    x, v = run.displacement[:, :3], run.velocity[:, :3]
    drift = x - np.column_stack([np.zeros(len(x)), x[:, :2]])
    rate = v - np.column_stack([np.zeros(len(v)), v[:, :2]])
    assert s.names == ("floor1", "floor2", "roof")
    assert np.array_equal(s.drift, drift) and np.allclose(s.drift_ratio, drift / HEIGHTS, rtol=1e-15, atol=0)
    assert np.allclose(s.shear, K * drift + C * rate, rtol=1e-12, atol=1e-12 * np.abs(s.shear).max())
    assert np.array_equal(s.residual_drift, drift[-1])
    reference = smdcli.simulate(smdcli.load(fine), method="DOP853", rtol=1e-12, atol=1e-14)
    xf, vf = reference.displacement[:, :3], reference.velocity[:, :3]
    drift_f = xf - np.column_stack([np.zeros(len(xf)), xf[:, :2]])
    rate_f = vf - np.column_stack([np.zeros(len(vf)), vf[:, :2]])
    for j in range(3):
        peak, at = located(reference.time, drift_f[:, j])
        assert s.peak_drift[j] == pytest.approx(peak, rel=1e-8) and s.peak_drift_time[j] == pytest.approx(at, abs=1e-4)
        assert s.peak_drift_ratio[j] == pytest.approx(peak / HEIGHTS[j], rel=1e-8)
        shear, at = located(reference.time, K[j] * drift_f[:, j] + C[j] * rate_f[:, j])
        assert s.peak_shear[j] == pytest.approx(shear, rel=1e-8) and s.shear_located[j]
        assert s.peak_drift[j] > np.abs(drift[:, j]).max()  # between samples, above the largest sample


def test_the_run_writes_storeys_and_prints_the_peak_drift_ratio(cli, tmp_path):
    """/storeys holds the histories (time x storey) and the peaks; the terminal a peak drift ratio per storey,
    --json the storeys' peaks."""
    path = tmp_path / "building.toml"
    path.write_text(BUILDING)
    ran = cli("simulate", path, "-o", tmp_path / "out", "--no-plots")
    assert ran.exit_code == 0, ran.output
    assert "drift    peak ratio floor1" in ran.output
    run = smdcli.simulate(path)
    with h5py.File(tmp_path / "out" / "building.h5") as f:
        g = f["storeys"]
        assert [n.decode() if isinstance(n, bytes) else n for n in g["storey"][()]] == ["floor1", "floor2", "roof"]
        assert g["drift"].shape == (len(run.time), 3)
        assert np.array_equal(g["peak_drift_ratio"][()], run.storeys.peak_drift_ratio)
        assert np.array_equal(g["residual_drift"][()], run.storeys.residual_drift)
        assert g["peak_shear"].attrs["units"] == "N"
    data = json.loads(cli("simulate", path, "-o", tmp_path / "out", "--no-plots", "--json").output)
    data = data[0] if isinstance(data, list) else data
    assert data["storeys"][2]["peak_drift_ratio"] == run.storeys.peak_drift_ratio[2]


@pytest.mark.parametrize("change,field,message", [
    ("storey_heights = [4.0, 3.5, 3.5]", "building.storey_heights", "expected 4 heights"),
    ('masses = ["floor1", "floor2", "roof"]', "building.storey_heights", "expected 3 heights"),
    ('masses = ["floor1", "florr2", "roof"]', "building.masses", "did you mean 'floor2'"),
    ("storey_heights = [4.0, -3.5, 3.5]", "building.storey_heights[1]", "expected a positive height"),
    ("[system]", "building", "needs the element form"),
])
def test_a_bad_building_table_is_one_line_exit_2(change, field, message, cli, tmp_path):
    """Heights that do not match the chain, an unknown mass, a height that is not positive: one line naming the
    field, nothing written."""
    text = BUILDING.replace('masses = ["floor1", "floor2", "roof"]\n', "") if "storey_heights" in change \
        and "-3.5" not in change else BUILDING
    if change == "[system]":
        text = ('[time]\nend = 1.0\nstep = 0.01\n[system]\ndofs = ["a"]\nM = [[1.0]]\nK = [[100.0]]\n'
                '[building]\nstorey_heights = [3.0]\n')
    elif "-3.5" in change:
        text = BUILDING.replace("storey_heights = [4.0, 3.5, 3.5]", change)
    elif "florr2" in change:
        text = BUILDING.replace('masses = ["floor1", "floor2", "roof"]', change)
    elif change.startswith("masses"):
        text = BUILDING.replace("storey_heights = [4.0, 3.5, 3.5]", "storey_heights = [4.0, 3.5]")
    path = tmp_path / "bad.toml"
    path.write_text(text)
    ran = cli("simulate", path, "-o", tmp_path / "out")
    assert ran.exit_code == 2 and field in ran.output and message in ran.output, ran.output
    assert len(ran.output.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_sweep_s_storey_metrics_are_each_member_s_simulation(cli, tmp_path):
    """smd sweep over the first storey's stiffness: metrics/peak_drift_ratio and residual_drift at each chain mass
    equal the storeys of each member simulated on its own (to 1e-9 of the peak: the members' own located peaks),
    NaN at the TMD; a scene without [building] has no storey metrics, and --metric peak_drift_ratio is refused."""
    path = tmp_path / "building.toml"
    path.write_text(BUILDING)
    ran = cli("sweep", path, "--param", "spring[0].k", "--values", "linspace(2e7,4e7,3)", "-o", tmp_path / "out", "--no-plots")
    assert ran.exit_code == 0, ran.output
    with h5py.File(tmp_path / "out" / "building_sweep.h5") as f:
        ratio, residual = f["metrics/peak_drift_ratio"][()], f["metrics/residual_drift"][()]
    for member, k in enumerate(np.linspace(2e7, 4e7, 3)):
        one = tmp_path / f"member{member}.toml"
        one.write_text(BUILDING.replace("k = 3.0e7", f"k = {float(k)!r}"))
        s = smdcli.simulate(one).storeys
        assert ratio[member, :3] == pytest.approx(s.peak_drift_ratio, rel=1e-9)
        assert residual[member, :3] == pytest.approx(s.residual_drift, rel=1e-9, abs=1e-9 * s.peak_drift.max())
        assert np.isnan(ratio[member, 3]) and np.isnan(residual[member, 3])
    plain = tmp_path / "plain.toml"
    plain.write_text(BUILDING.split("[building]")[0])
    ran = cli("sweep", plain, "--param", "spring[0].k", "--values", "linspace(2e7,4e7,3)", "-o", tmp_path / "plain", "--no-plots")
    with h5py.File(tmp_path / "plain" / "plain_sweep.h5") as f:
        assert "peak_drift_ratio" not in f["metrics"] and "peak_displacement" in f["metrics"]
    ran = cli("sweep", plain, "--param", "spring[0].k", "--values", "linspace(2e7,4e7,3)", "--metric", "peak_drift_ratio",
              "-o", tmp_path / "none")
    assert ran.exit_code == 2 and "needs a [building] table" in ran.output, ran.output


YIELDING = BUILDING.split("[[spring]]")[0].replace("end = 3.0", "end = 2.0") + """
[[spring]]
connects = ["ground", "floor1"]
law = "bilinear"
k = 3.0e7
fy = 9.0e4
hardening = 0.05
[[spring]]
connects = ["floor1", "floor2"]
law = "bilinear"
k = 2.5e7
fy = 6.0e4
hardening = 0.05
[[spring]]
connects = ["floor2", "roof"]
k = 2.0e7
[[spring]]
connects = ["roof", "tmd"]
k = 5.0e5
[[damper]]
connects = ["ground", "floor1"]
c = 6.0e4
[[damper]]
connects = ["floor2", "roof"]
c = 4.0e4
""" + BUILDING[BUILDING.index("[ground_motion]"):]


def test_a_yielding_storeys_peak_drift_is_its_unloadings_not_a_sample(tmp_path, cli):
    """Two storeys yield: each one's peak drift is where it unloads, an event. On a 20 ms grid the peak is that
    event's drift, as on a grid 200 times finer to 1e-9 (the same event states, found by the exact run whatever the
    grid), above every sample of the fine grid, and the samples of the coarse grid miss it by more than 1e-4; a
    sweep's peak_drift_ratio (members solved one by one) is the same number. (The elastic third storey's peak falls
    in a step holding the others' events, where the samples stand: 3e-6 short here.)"""
    path, fine = tmp_path / "yielding.toml", tmp_path / "fine.toml"
    path.write_text(YIELDING)
    fine.write_text(YIELDING.replace("step = 0.02", "step = 0.0001"))
    coarse_run, fine_run = smdcli.simulate(path), smdcli.simulate(fine)
    assert {kind for _, _, kind in coarse_run.nonsmooth.events} == {"yield", "unload"}
    coarse, sampled = coarse_run.storeys, fine_run.storeys
    np.testing.assert_allclose(coarse.peak_drift[:2], sampled.peak_drift[:2], rtol=1e-9)
    assert np.all(coarse.peak_drift[:2] >= np.abs(sampled.drift[:, :2]).max(axis=0) * (1 - 1e-12))
    short = 1 - np.abs(coarse.drift).max(axis=0) / coarse.peak_drift
    assert short[:2].min() > 1e-4, short  # what reading the samples lost at the yielding storeys
    ran = cli("sweep", path, "--param", "spring[2].k", "--values", "2e7", "-o", tmp_path / "out", "--no-plots", "-q")
    assert ran.exit_code == 0, ran.output
    with h5py.File(tmp_path / "out" / "yielding_sweep.h5") as f:
        np.testing.assert_allclose(f["metrics/peak_drift_ratio"][0, :3], coarse.peak_drift_ratio, rtol=1e-12)
