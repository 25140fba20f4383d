"""`smd spectrum` and the records it reads: spectra against independent solutions, the file and its errors."""

import json
import math
import runpy
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import lfilter, lsim

from smdcli.scenario.record_files import read_record
from smdcli.scenario.spec import STANDARD_GRAVITY
from smdcli.analysis.spectrum import response_spectrum

RECORDS = Path(__file__).resolve().parent.parent / "records"
SYNTHETIC = RECORDS / "synthetic_20s_100hz.csv"


def _oscillator(period: float, zeta: float, step: float) -> tuple[list, list, list]:
    """y'' + 2 zeta w y' + w^2 y = -a(t), a held linearly between samples `step` apart, as scipy's lsim holds it (its
    first-order hold: x+ = Phi x + B0 a_k + B1 a_k+1, from scipy.linalg.expm): the transfer function from a to y
    (numerator, denominator) and the numerator of the free response a state x0 = B1 leaves, which lfilter's zero past
    puts at the start (lsim starts at rest)."""
    w = 2 * math.pi / period
    augmented = np.zeros((4, 4))
    augmented[:2, :2] = [[0.0, step], [-w * w * step, -2 * zeta * w * step]]
    augmented[1, 2] = -step  # B = (0, -1)
    augmented[2, 3] = 1.0
    exponential = expm(augmented)
    (a, b), (c, d) = exponential[:2, :2]
    held, ramp = exponential[:2, 2] - exponential[:2, 3], exponential[:2, 3]

    def numerator(column):  # the first row of adj(zI - Phi) times the column: coefficients of z and 1
        return [column[0], -d * column[0] + b * column[1]]

    n0, n1 = numerator(held), numerator(ramp)
    return [n1[0], n1[1] + n0[0], n0[1]], [1.0, -(a + d), a * d - b * c], n1


def _response(time, acceleration, period, zeta, finer):
    """y on a grid `finer` times finer than the record's: the first-order-hold recursion of lsim, run by lfilter
    (lsim's own loop in Python took 37 s of CI for these references)."""
    fine = np.linspace(time[0], time[-1], (len(time) - 1) * finer + 1)
    a = np.interp(fine, time, acceleration)
    numerator, denominator, free = _oscillator(period, zeta, fine[1] - fine[0])
    start = np.zeros_like(a)
    start[0] = a[0]
    return lfilter(numerator, denominator, a) - lfilter(free, denominator, start)


def _peak(time, acceleration, period, zeta, finer):
    """max |y| of _response."""
    return np.abs(_response(time, acceleration, period, zeta, finer)).max()


def test_the_reference_recursion_is_lsim():
    """_response is lsim's solution, on a record that starts off zero, short and long periods, on its grid and a 20x
    finer one, to 1e-7 of its peak, far inside the 2e-5 asked of the spectrum against it (a transfer function's rounding
    grows as its poles near 1, as a long period's on a fine grid: 5e-9 at period / step = 8e4; the spectrum's
    references reach 1e4)."""
    time = np.linspace(0.0, 2.0, 801)
    acceleration = np.sin(7 * time) + np.random.default_rng(1).normal(size=time.size)
    for period, zeta, finer in ((0.0103, 0.0, 1), (0.5, 0.05, 1), (10.0, 0.2, 1), (10.0, 0.0, 20), (0.0103, 0.2, 20)):
        w = 2 * math.pi / period
        fine = np.linspace(time[0], time[-1], (len(time) - 1) * finer + 1)
        _, y, _ = lsim(([-1.0], [1.0, 2 * zeta * w, w * w]), np.interp(fine, time, acceleration), fine)
        ours = _response(time, acceleration, period, zeta, finer)
        assert np.abs(ours - y).max() <= 1e-7 * np.abs(y).max(), (period, zeta, finer)


def test_spectrum_of_the_shipped_record_matches_lsim_on_a_20x_finer_grid():
    """Every 20th of 200 periods (0.01-10 s) x 3 of the 5 damping ratios: within 1e-3 of lsim on a 20x finer grid
    (whose own sampling misses short periods' peaks by up to 4e-4); two short periods within 2e-5 of a 400x finer
    one."""
    record = read_record(SYNTHETIC)
    periods = np.logspace(-2, 1, 200)
    dampings = np.array([0.0, 0.02, 0.05, 0.1, 0.2])
    spectrum = response_spectrum(record.time, record.acceleration, periods, dampings)
    assert spectrum.Sd.shape == (5, 200)
    for i, zeta in list(enumerate(dampings))[::2]:
        for j in range(0, 200, 20):
            reference = _peak(record.time, record.acceleration, periods[j], zeta, 20)
            assert spectrum.Sd[i, j] == pytest.approx(reference, rel=1e-3), (periods[j], zeta)
    for i, j in ((0, 1), (4, 50)):  # T = 0.0103 and 0.0567 s
        finer = _peak(record.time, record.acceleration, periods[j], dampings[i], 400)
        assert spectrum.Sd[i, j] == pytest.approx(finer, rel=2e-5), (periods[j], dampings[i])
    w = 2 * math.pi / periods
    np.testing.assert_allclose(spectrum.Sv, spectrum.Sd * w, rtol=1e-15)
    np.testing.assert_allclose(spectrum.Sa, spectrum.Sd * w**2, rtol=1e-15)


def test_the_peak_between_samples_is_the_closed_form_one():
    """A constant acceleration a0 from rest: the undamped oscillator peaks at 2 a0 / w^2 at t = T / 2, between the
    record's samples for these periods; the damped one at (a0 / w^2)(1 + exp(-zeta pi / sqrt(1 - zeta^2)))."""
    time = np.arange(0.0, 2.0 + 1e-9, 0.01)
    a0 = 3.0
    periods = np.array([0.0137, 0.0531, 0.2173, 0.7071])
    spectrum = response_spectrum(time, np.full_like(time, a0), periods, np.array([0.0, 0.05]))
    w = 2 * math.pi / periods
    np.testing.assert_allclose(spectrum.Sd[0], 2 * a0 / w**2, rtol=1e-12)  # located, not sampled: to rounding
    overshoot = math.exp(-0.05 * math.pi / math.sqrt(1 - 0.05**2))
    np.testing.assert_allclose(spectrum.Sd[1], a0 / w**2 * (1 + overshoot), rtol=1e-12)


def test_the_shipped_record_is_made_by_its_script():
    """records/make_synthetic.py recreates records/synthetic_20s_100hz.csv from its seed."""
    module = runpy.run_path(str(RECORDS / "make_synthetic.py"))
    t, a = module["synthetic_record"]()
    data = np.loadtxt(SYNTHETIC, delimiter=",", skiprows=1)
    np.testing.assert_allclose(data[:, 0], t, atol=5e-3)
    np.testing.assert_allclose(data[:, 1], a, atol=1e-6)
    assert len(t) == 2001 and t[-1] == pytest.approx(20.0) and np.abs(a).max() == pytest.approx(0.3)


def test_spectrum_writes_the_documented_file_plot_and_json(cli, tmp_path):
    result = cli("spectrum", SYNTHETIC, "--periods", "logspace(-1,0,7)", "--damping", "0.02,0.05", "-o", tmp_path,
                 "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["periods"] == 7 and data["damping"] == [0.02, 0.05]
    # The synthetic record's velocity ends near rest, but integrated twice it drifts to -0.749 m (99 % of its peak)
    assert len(data["warnings"]) == 1 and "displacement integrated from the record ends at -0.7489 m" in \
        data["warnings"][0]
    assert data["pga_m_s2"] == pytest.approx(0.3 * STANDARD_GRAVITY)
    h5, png = tmp_path / "synthetic_20s_100hz_spectrum.h5", tmp_path / "synthetic_20s_100hz_spectrum.png"
    assert data["outputs"] == [str(h5), str(png)] and png.stat().st_size > 10_000
    with h5py.File(h5) as f:
        assert f.attrs["kind"] == "spectrum"
        np.testing.assert_allclose(f["period"][:], np.logspace(-1, 0, 7))
        np.testing.assert_array_equal(f["damping"][:], [0.02, 0.05])
        for name, units in (("Sd", "m"), ("Sv", "m/s"), ("Sa", "m/s^2")):
            assert f[name].shape == (2, 7) and f[name].attrs["units"] == units
            assert f[name].dims[0][0].name == "/damping" and f[name].dims[1][0].name == "/period"
        assert data["peaks"][1]["peak_Sa_m_s2"] == pytest.approx(f["Sa"][1].max())
        assert f["record/acceleration"].shape == (2001,)
    text = cli("spectrum", SYNTHETIC, "--periods", "0.5", "-o", tmp_path, "--no-plots").stdout
    assert "PGA 0.3 g" in text and "zeta 0.05" in text


def test_records_in_whitespace_columns_with_units_scale_and_shift(tmp_path):
    path = tmp_path / "rec.txt"
    path.write_text("# a comment\ntime accel\n0.0 0.1\n0.5 0.2\n1.0 -0.1\n")
    record = read_record(path, units="m/s^2", scale=2.0, shift=0.5)
    np.testing.assert_allclose(record.acceleration, [0.7, 0.9, 0.3])
    np.testing.assert_allclose(read_record(path).acceleration, np.array([0.1, 0.2, -0.1]) * STANDARD_GRAVITY)


def test_a_record_whose_velocity_drifts_gets_a_warning(cli, tmp_path):
    path = tmp_path / "offset.csv"
    t = np.arange(0, 5.0, 0.01)
    path.write_text("\n".join(f"{x:.2f},{0.1 * math.sin(10 * x) + 0.02:.6f}" for x in t) + "\n")
    result = cli("spectrum", path, "--periods", "0.2,1", "-o", tmp_path, "--no-plots")
    assert result.exit_code == 0
    assert "warning:" in result.stdout and "baseline correction" in result.stdout
    assert "the velocity integrated" in result.stdout
    synthetic = cli("spectrum", SYNTHETIC, "--periods", "1", "-o", tmp_path, "--no-plots").stdout
    assert "the velocity integrated" not in synthetic and "the displacement integrated" in synthetic


@pytest.mark.parametrize("text, args, expected", [
    ("0,1\n0.02,2\n0.01,3\n", (), "strictly increasing times"),
    ("0,1\n0.01,nan\n0.02,3\n", (), "expected finite numbers"),
    ("0,1\n0.01\n0.02,3\n", (), "expected two columns"),
    ("0,1\n0.01,2\n0.02,3\n", ("--units", "furlong/s^2"), "units: expected one of 'g', 'm/s^2', 'cm/s^2', 'mm/s^2', 'gal'"),
    ("0,1\n0.01,2\n0.03,3\n", (), "expected uniformly sampled times"),
    ("0,1\n0.01,2\n0.02,3\n", ("--periods", "-1,2"), "--periods: expected positive periods"),
    ("0,1\n0.01,2\n0.02,3\n", ("--damping", "0.05,-0.1"), "--damping: expected damping ratios >= 0"),
])
def test_bad_records_and_options_exit_2_with_one_line_and_write_nothing(cli, tmp_path, text, args, expected):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    out = tmp_path / "out"
    result = cli("spectrum", path, *args, "-o", out)
    assert result.exit_code == 2, result.output
    assert expected in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "Traceback" not in result.output
    assert not out.exists() or not list(out.iterdir())


def test_a_long_record_is_measured_in_bounded_pieces_with_the_same_result(monkeypatch):
    """Oscillators in groups and time in blocks (here a few hundred values each, as an hour-long record would be):
    the same spectrum, bit for bit, as in one piece; the progress callback hears of every oscillator."""
    import smdcli.analysis.spectrum as spectrum_mod

    record = read_record(SYNTHETIC)
    periods, dampings = np.logspace(-2, 1, 23), np.array([0.0, 0.05])
    whole = response_spectrum(record.time, record.acceleration, periods, dampings)
    monkeypatch.setattr(spectrum_mod, "STATE_VALUES", 5 * len(record.time))
    heard = []
    pieces = response_spectrum(record.time, record.acceleration, periods, dampings, heard.append)
    np.testing.assert_array_equal(pieces.Sd, whole.Sd)
    assert heard == [5] * 9 + [1]
