"""`smd record`: intensity measures against direct formulas written here, baseline correction and filtering by
their defining properties, and the same processing inside a [ground_motion] table."""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
from conftest import ROOT
from typer.testing import CliRunner

from smdcli.analysis.record import process
from smdcli.cli import app

RECORD = ROOT / "records" / "synthetic_20s_100hz.csv"
G = 9.80665


def shipped():
    data = np.loadtxt(RECORD, delimiter=",", skiprows=1)
    return data[:, 0], data[:, 1] * G


def direct_measures(t, a):
    """PGV, PGD, Arias, CAV, D5-95, D5-75 by plain formulas: loops and closed-form integrals of the straight lines."""
    dt = t[1] - t[0]
    n = len(a)
    v = np.zeros(n)
    for k in range(n - 1):
        v[k + 1] = v[k] + dt * (a[k] + a[k + 1]) / 2
    # d(T) = integral_0^T (T - s) a(s) ds, the straight line on each interval integrated in closed form
    slope = np.diff(a) / dt
    d = np.zeros(n)
    for m in range(1, n):
        T = t[m]
        lo = t[:m]
        a0, s = a[:m], slope[:m]
        # integral over [lo, hi] of (T - x)(a0 + s (x - lo)) dx, with u = x - lo in [0, dt]
        c = T - lo
        d[m] = np.sum(c * a0 * dt + (c * s - a0) * dt**2 / 2 - s * dt**3 / 3)
    sq = a * a
    running = np.concatenate([[0.0], np.cumsum((sq[:-1] + sq[1:]) * dt / 2)])
    arias = math.pi / (2 * G) * running[-1]

    def when(fraction):
        level = fraction * running[-1]
        k = next(i for i in range(n) if running[i] >= level)
        return t[k - 1] + dt * (level - running[k - 1]) / (running[k] - running[k - 1])

    cav = sum(dt * (abs(a[k]) + abs(a[k + 1])) / 2 for k in range(n - 1))
    return {"pgv": np.abs(v).max(), "pgd": np.abs(d).max(), "arias": arias, "cav": cav,
            "d5_95": when(0.95) - when(0.05), "d5_75": when(0.75) - when(0.05), "final_d": d[-1]}


def test_intensity_measures_equal_direct_formulas():
    t, a = shipped()
    m = process(t, a).measures
    ref = direct_measures(t, a)
    assert m.pga == pytest.approx(np.abs(a).max(), rel=1e-15)
    for name in ("pgv", "pgd", "arias", "cav", "d5_95", "d5_75"):
        assert getattr(m, name) == pytest.approx(ref[name], rel=1e-9), name
    assert process(t, a).displacement[-1] == pytest.approx(ref["final_d"], rel=1e-9)


def test_housner_intensity_is_the_pseudo_velocity_area():
    from smdcli.analysis.spectrum import response_spectrum

    t, a = shipped()
    periods = np.linspace(0.1, 2.5, 241)
    Sv = response_spectrum(t, a, periods, np.array([0.05])).Sv[0]
    assert process(t, a).measures.housner == pytest.approx(np.sum((Sv[1:] + Sv[:-1]) / 2 * np.diff(periods)), rel=1e-12)


@pytest.mark.parametrize("baseline, degree", [("linear", 1), ("quadratic", 2)])
def test_baseline_correction_removes_a_polynomial_drift_to_rounding(baseline, degree):
    t, a = shipped()
    drift = sum(c * t**p for p, c in enumerate((0.03, -0.004, 2e-4)[:degree + 1]))
    clean = process(t, a, baseline).acceleration
    drifted = process(t, a + drift, baseline).acceleration
    assert np.abs(drifted - clean).max() < 1e-12 * np.abs(a).max()
    # and the drift alone is removed entirely
    assert np.abs(process(t, drift, baseline).acceleration).max() < 1e-13 * np.abs(drift).max()


def test_the_zero_phase_butterworth_passes_halves_and_stops():
    """Applied forwards and backwards, a Butterworth's gain at its cutoff is 1/sqrt(2) squared: a sine there comes
    out at half its amplitude, in phase; one a decade inside the band passes whole, one a decade out is gone."""
    t = np.arange(0, 60.0, 0.005)
    middle = (t > 20) & (t < 40)
    for f, gain in ((0.2, 0.5), (2.0, 1.0), (20.0, 0.5), (0.02, 0.0), (200.0 / 2.5, 0.0)):
        a = np.sin(2 * math.pi * f * t)
        out = process(t, a, band=(0.2, 20.0), order=4).acceleration
        expected = gain * a
        assert np.abs(out[middle] - expected[middle]).max() < 2e-3, f


def test_smd_record_writes_the_file_plot_and_json(tmp_path):
    done = CliRunner().invoke(app, ["record", str(RECORD), "--baseline", "quadratic", "--filter", "0.1,25",
                                    "-o", str(tmp_path), "--json"])
    assert done.exit_code == 0, done.output
    data = json.loads(done.stdout)
    with h5py.File(tmp_path / "synthetic_20s_100hz_record.h5") as f:
        assert f.attrs["baseline"] == "quadratic" and list(f.attrs["filter_hz"]) == [0.1, 25.0]
        assert f.attrs["arias_intensity"] == pytest.approx(data["arias_intensity_m_s"], rel=1e-15)
        a = f["acceleration"][:]
        husid = f["husid"][:]
        t = f["time"][:]
    ref = direct_measures(t, a)
    assert data["d5_95_s"] == pytest.approx(ref["d5_95"], rel=1e-9)
    assert husid[0] == 0 and husid[-1] == pytest.approx(1.0, rel=1e-15)
    assert (tmp_path / "synthetic_20s_100hz_record.png").stat().st_size > 20_000


@pytest.mark.parametrize("args, message", [
    (["--baseline", "cubic"], "--baseline: expected one of none, linear, quadratic"),
    (["--filter", "0.1,80"], "the Nyquist frequency 50 Hz"),
    (["--filter", "abc"], "--filter: expected LOW,HIGH in Hz"),
    (["--filter", "0,0"], "not both 0"),
    (["--order", "0"], "--order: expected a Butterworth order from 1 to 10"),
])
def test_bad_record_options_exit_2(tmp_path, args, message):
    done = CliRunner().invoke(app, ["record", str(RECORD), *args, "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and message in done.output and "Traceback" not in done.output
    assert not (tmp_path / "o").exists()


def test_ground_motion_baseline_and_filter_process_the_record_as_smd_record_does(tmp_path):
    """A scene shaken by the record with baseline and filter keys equals the same scene shaken by the processed
    acceleration that `smd record` writes."""
    from smdcli import scenario
    from smdcli.model import build, time_grid
    from smdcli.solvers import solve
    from smdcli.solvers.base import Tolerances

    runner = CliRunner()
    assert runner.invoke(app, ["record", str(RECORD), "--baseline", "linear", "--filter", "0.2,20", "--order", "3",
                               "-o", str(tmp_path), "--no-plots"]).exit_code == 0
    with h5py.File(tmp_path / "synthetic_20s_100hz_record.h5") as f:
        t, a = f["time"][:], f["acceleration"][:]
    processed_csv = tmp_path / "processed.csv"
    processed_csv.write_text("".join(f"{ti!r},{ai!r}\n" for ti, ai in zip(t.tolist(), a.tolist())))
    base = ('[time]\nend = 20.0\nstep = 0.01\n[[mass]]\nname = "m"\nm = 1.0\n[[spring]]\nconnects = ["ground", "m"]\n'
            'k = 40.0\n[[damper]]\nconnects = ["ground", "m"]\nc = 0.6\n[ground_motion]\nquantity = "acceleration"\n'
            'type = "table"\n')
    keyed = base + f'file = "{RECORD}"\nunits = "g"\nbaseline = "linear"\nfilter = [0.2, 20.0]\nfilter_order = 3\n'
    plain = base + f'file = "{processed_csv}"\nunits = "m/s^2"\n'
    runs = []
    for text in (keyed, plain):
        sc = scenario.parse(text, str(tmp_path / "scene.toml"))
        runs.append(solve(build(sc), time_grid(sc.time), "exact", Tolerances()).displacement)
    assert np.abs(runs[0] - runs[1]).max() < 1e-12 * np.abs(runs[1]).max()


@pytest.mark.parametrize("extra, message", [
    ('baseline = "cubic"\n', "ground_motion.baseline"),
    ("filter = [0.1, 80.0]\n", "Nyquist frequency 50 Hz"),
    ("filter_order = 4\n", "expected it with filter"),
])
def test_bad_ground_motion_processing_is_one_line(tmp_path, extra, message):
    scene = tmp_path / "scene.toml"
    scene.write_text('[time]\nend = 1.0\n[[mass]]\nname = "m"\nm = 1.0\n[[spring]]\nconnects = ["ground", "m"]\n'
                     'k = 4.0\n[ground_motion]\nquantity = "acceleration"\ntype = "table"\n'
                     f'file = "{RECORD}"\nunits = "g"\n{extra}')
    done = CliRunner().invoke(app, ["simulate", str(scene), "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and message in done.output and "Traceback" not in done.output


def test_a_record_whose_measures_overflow_is_refused(tmp_path):
    path = tmp_path / "huge.csv"
    path.write_text("0,1e200\n0.01,-1e200\n0.02,1e200\n0.03,0\n")
    done = CliRunner().invoke(app, ["record", str(path), "--units", "m/s^2", "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and "overflow double precision" in done.output and "Traceback" not in done.output
    assert not (tmp_path / "o").exists()
