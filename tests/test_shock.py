"""The shock response spectrum (`smd spectrum --kind srs`) against the closed-form response of a 1-DOF oscillator
to a half-sine base pulse, over the pulse and the residual free motion after it."""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
from conftest import ROOT
from scipy.optimize import minimize_scalar

from smdcli.analysis.shock import shock_response_spectrum
from smdcli.kernels.oscillator import DISPLACEMENT, extremes

TAU, PEAK = 0.011, 1.0  # s, record units


def closed_form_absolute_acceleration(w: float, zeta: float, t):
    """x'' of a mass on a spring and damper whose base accelerates as PEAK sin(pi t / TAU) on [0, TAU], then 0: the
    harmonic particular solution plus the homogeneous one from rest, then free decay from the pulse's end."""
    W = math.pi / TAU
    # particular y = B1 sin Wt + B2 cos Wt of y'' + 2 zeta w y' + w^2 y = -PEAK sin Wt
    M = np.array([[w * w - W * W, -2 * zeta * w * W], [2 * zeta * w * W, w * w - W * W]])
    B1, B2 = np.linalg.solve(M, [-PEAK, 0.0])
    wd = w * math.sqrt(1 - zeta * zeta)
    C1 = -B2
    C2 = (zeta * w * C1 - B1 * W) / wd

    def state(s):
        e = np.exp(-zeta * w * s)
        y = B1 * np.sin(W * s) + B2 * np.cos(W * s) + e * (C1 * np.cos(wd * s) + C2 * np.sin(wd * s))
        v = (B1 * W * np.cos(W * s) - B2 * W * np.sin(W * s)
             + e * ((-zeta * w * C1 + wd * C2) * np.cos(wd * s) + (-zeta * w * C2 - wd * C1) * np.sin(wd * s)))
        return y, v

    t = np.asarray(t, dtype=float)
    y, v = state(np.minimum(t, TAU))
    y_end, v_end = state(TAU)
    s = np.maximum(t - TAU, 0.0)
    e = np.exp(-zeta * w * s)
    free_y = e * (y_end * np.cos(wd * s) + (v_end + zeta * w * y_end) / wd * np.sin(wd * s))
    free_v = e * (v_end * np.cos(wd * s) - (w * w * y_end + zeta * w * v_end) / wd * np.sin(wd * s))
    y, v = np.where(t <= TAU, y, free_y), np.where(t <= TAU, v, free_v)
    return -(2 * zeta * w * v + w * w * y)


def closed_form_extremes(f_hz: float, zeta: float) -> tuple[float, float]:
    """(largest, smallest) absolute acceleration over the pulse and 1.25 periods after it: densely sampled, each
    extreme polished by a bounded scalar minimisation around its sample."""
    w = 2 * math.pi * f_hz
    t = np.linspace(0.0, TAU + 1.25 / f_hz, 400_001)
    x = closed_form_absolute_acceleration(w, zeta, t)
    dt = t[1] - t[0]
    found = []
    for sign, i in ((1.0, int(np.argmax(x))), (-1.0, int(np.argmin(x)))):
        best = minimize_scalar(lambda s: -sign * closed_form_absolute_acceleration(w, zeta, s),
                               bounds=(max(0.0, t[i] - dt), t[i] + dt), method="bounded", options={"xatol": 1e-14})
        found.append(max(sign * x[i], -best.fun) * sign)
    return found[0], found[1]


def half_sine(samples: int) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, TAU, samples)
    a = PEAK * np.sin(math.pi * t / TAU)
    a[-1] = 0.0
    return t, a


FREQUENCIES = np.array([5.0, 20.0, 45.0, 90.91, 150.0, 400.0, 1000.0, 2500.0, 6000.0, 12000.0])


@pytest.mark.parametrize("q", [10.0, 50.0])
def test_half_sine_srs_equals_the_closed_form(q):
    samples = 100_001
    t, a = half_sine(samples)
    srs = shock_response_spectrum(t, a, FREQUENCIES, np.array([q]))
    # the record's straight lines between samples differ from the sine by (pi dt / TAU)^2 / 12 of the response
    interpolation = (math.pi * (t[1] - t[0]) / TAU) ** 2 / 12
    assert interpolation < 1e-10
    for j, f in enumerate(FREQUENCIES):
        high, low = closed_form_extremes(f, 1 / (2 * q))
        scale = max(high, -low)
        assert abs(srs.positive[0, j] - high) < 1e-8 * scale, (f, srs.positive[0, j], high)
        assert abs(srs.negative[0, j] - low) < 1e-8 * scale, (f, srs.negative[0, j], low)
        assert srs.maximax[0, j] == pytest.approx(scale, rel=1e-8)


def test_the_error_falls_as_the_square_of_the_sampling_step():
    """The kernel is exact for the record it is given; what remains is the record's own straight-line sampling."""
    errors = []
    for samples in (1_001, 10_001):
        t, a = half_sine(samples)
        srs = shock_response_spectrum(t, a, np.array([150.0]), np.array([10.0]))
        high, _ = closed_form_extremes(150.0, 0.05)
        errors.append(abs(srs.positive[0, 0] - high) / high)
    assert 70 < errors[0] / errors[1] < 130  # 10x finer sampling, 100x smaller error
    dt = TAU / 1000
    assert errors[0] < 2 * (math.pi * dt / TAU) ** 2 / 12


def test_a_straight_line_record_is_solved_to_rounding():
    """A triangular pulse is linear between its samples: the peak displacement agrees with a DOP853 run at rtol
    1e-13 whose extremes are located on its dense output."""
    from scipy.integrate import solve_ivp

    t = np.array([0.0, 0.004, 0.01, 0.03])
    a = np.array([0.0, 3.0, -1.0, 0.0])
    w, zeta = 2 * math.pi * 37.0, 0.03
    time = np.linspace(0.0, 0.03, 3001)  # a uniform record holding the same straight lines
    acc = np.interp(time, t, a)
    found = extremes(acc, time[1] - time[0], np.array([w]), np.array([zeta]), DISPLACEMENT, 0.0, threads=1)[0]

    def rhs(s, y):
        return [y[1], -np.interp(s, t, a) - 2 * zeta * w * y[1] - w * w * y[0]]

    best_hi, best_lo = 0.0, 0.0
    y = [0.0, 0.0]
    for lo, hi in zip(t[:-1], t[1:]):  # restarted at each kink of the input
        sol = solve_ivp(rhs, (lo, hi), y, method="DOP853", rtol=1e-13, atol=1e-16, dense_output=True)
        s = np.linspace(lo, hi, 20001)
        x = sol.sol(s)[0]
        for sign in (1.0, -1.0):
            i = int(np.argmax(sign * x))
            res = minimize_scalar(lambda u: -sign * sol.sol(u)[0], bounds=(s[max(i - 1, 0)], s[min(i + 1, len(s) - 1)]),
                                  method="bounded", options={"xatol": 1e-15})
            value = -res.fun * sign
            best_hi, best_lo = (max(best_hi, value), best_lo) if sign > 0 else (best_hi, min(best_lo, value))
        y = sol.y[:, -1]
    scale = max(best_hi, -best_lo)
    assert abs(found[0] - best_hi) < 1e-11 * scale and abs(found[2] - best_lo) < 1e-11 * scale


def test_smd_spectrum_kind_srs_writes_the_file_and_plot(tmp_path):
    from typer.testing import CliRunner

    from smdcli.cli import app

    record = ROOT / "records" / "half_sine_11ms_50g.csv"
    done = CliRunner().invoke(app, ["spectrum", str(record), "--kind", "srs", "--q", "10,25", "--frequencies",
                                    "10,100,1000", "-o", str(tmp_path), "--json"])
    assert done.exit_code == 0, done.output
    data = json.loads(done.stdout)
    assert data["kind"] == "srs" and [p["q"] for p in data["peaks"]] == [10.0, 25.0]
    with h5py.File(tmp_path / "half_sine_11ms_50g_srs.h5") as f:
        assert f["maximax"].shape == (2, 3) and f["maximax"].attrs["units"] == "g"
        assert list(f["frequency"][:]) == [10.0, 100.0, 1000.0]
        # far above the pulse's frequencies the mass follows the base: maximax -> the peak, 50 g
        assert f["maximax"][0, 2] == pytest.approx(50.0, rel=0.02)
    assert (tmp_path / "half_sine_11ms_50g_srs.png").stat().st_size > 10_000


@pytest.mark.parametrize("args, message", [
    (["--kind", "srs", "--periods", "1"], "--periods and --damping belong to --kind pseudo"),
    (["--q", "10"], "--q and --frequencies belong to --kind srs"),
    (["--kind", "srs", "--q", "0"], "--q: expected quality factors > 0"),
    (["--kind", "srs", "--frequencies", "-5"], "--frequencies: expected natural frequencies in Hz > 0"),
    (["--kind", "shock"], "--kind: expected one of pseudo, srs"),
])
def test_bad_srs_options_are_one_line_and_exit_2(tmp_path, args, message):
    from typer.testing import CliRunner

    from smdcli.cli import app

    record = ROOT / "records" / "half_sine_11ms_50g.csv"
    done = CliRunner().invoke(app, ["spectrum", str(record), *args, "-o", str(tmp_path / "out")])
    assert done.exit_code == 2 and message in done.output and "Traceback" not in done.output
    assert not (tmp_path / "out").exists()
