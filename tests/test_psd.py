"""`smd psd`: random vibration against closed forms (white noise on a 1-DOF), an independent quadrature of
|H|^2 S written here (band-limited profiles, 2 DOFs) and Miles' equation where its assumptions hold."""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
from conftest import ROOT, SCENARIOS
from scipy.integrate import quad
from typer.testing import CliRunner

from smdcli.cli import app

G = 9.80665
PROFILE = ROOT / "records" / "navmat_p9492_profile.csv"
m, k, zeta = 0.5, 3.0e6, 0.05
wn = math.sqrt(k / m)
c = 2 * zeta * math.sqrt(k * m)


def scene(tmp_path, text=None):
    path = tmp_path / "one.toml"
    path.write_text(text or f'[time]\nend = 1.0\n[[mass]]\nname = "board"\nm = {m!r}\n[[spring]]\n'
                    f'connects = ["ground", "board"]\nk = {k!r}\n[[damper]]\nconnects = ["ground", "board"]\n'
                    f'c = {c!r}\n')
    return path


def run(*args):
    done = CliRunner().invoke(app, ["psd", *map(str, args), "--json", "--no-plots"])
    assert done.exit_code == 0, done.output
    return json.loads(done.stdout)


def test_white_noise_on_a_1dof_equals_the_closed_forms(tmp_path):
    level = 0.04  # g^2/Hz
    S = level * G**2
    data = run(scene(tmp_path), "--input", f"white:{level}", "-o", tmp_path)
    rms = data["rms"]
    # sigma_x^2 = S / (8 zeta wn^3), sigma_v^2 = S / (8 zeta wn), absolute acceleration S pi fn (1 + 4 zeta^2) / (4 zeta)
    assert rms["displacement"]["board"] == pytest.approx(math.sqrt(S / (8 * zeta * wn**3)), rel=1e-10)
    assert rms["velocity"]["board"] == pytest.approx(math.sqrt(S / (8 * zeta * wn)), rel=1e-10)
    fn = wn / (2 * math.pi)
    exact_a = math.sqrt(S * math.pi * fn * (1 + 4 * zeta**2) / (4 * zeta))
    assert rms["acceleration"]["board"] == pytest.approx(exact_a, rel=1e-10)
    assert rms["spring_force"]["spring[0]"] == pytest.approx(k * math.sqrt(S / (8 * zeta * wn**3)), rel=1e-10)
    assert rms["damper_force"]["damper[0]"] == pytest.approx(c * math.sqrt(S / (8 * zeta * wn)), rel=1e-10)
    # Miles' equation is the light-damping limit: the exact RMS is sqrt(1 + 4 zeta^2) times it
    assert data["rms_acceleration_g"]["board"] / data["miles_grms_g"] == pytest.approx(math.sqrt(1 + 4 * zeta**2),
                                                                                     rel=1e-10)


def test_a_force_psd_on_a_mass(tmp_path):
    level = 3.0  # N^2/Hz
    data = run(scene(tmp_path), "--input", f"white:{level}", "--on", "board", "-o", tmp_path)
    # x'' + 2 zeta wn x' + wn^2 x = F / m
    assert data["rms"]["displacement"]["board"] == pytest.approx(math.sqrt(level / m**2 / (8 * zeta * wn**3)),
                                                                 rel=1e-10)
    assert data["input"] == "force on board"


def _profile(f):
    table = np.loadtxt(PROFILE, delimiter=",", skiprows=3)
    return float(np.exp(np.interp(np.log(f), np.log(table[:, 0]), np.log(table[:, 1])))) * G**2, table[:, 0]


def test_a_band_limited_profile_equals_an_independent_quadrature(tmp_path):
    data = run(scene(tmp_path), "--input", PROFILE, "-o", tmp_path)
    _, breaks = _profile(100.0)
    fn = wn / (2 * math.pi)

    def h2(f, kind):
        w = 2 * math.pi * f
        H = 1 / (wn**2 - w**2 + 2j * zeta * wn * w)  # relative displacement per unit base acceleration
        return abs({"x": H, "a": (wn**2 + 2j * zeta * wn * w) * H}[kind]) ** 2

    for kind, key in (("x", "displacement"), ("a", "acceleration")):
        total = sum(quad(lambda f: h2(f, kind) * _profile(f)[0], lo, hi, points=[fn] if lo < fn < hi else None,
                         epsabs=0, epsrel=1e-12, limit=1000)[0] for lo, hi in zip(breaks[:-1], breaks[1:]))
        assert data["rms"][key]["board"] == pytest.approx(math.sqrt(total), rel=1e-6), key
    assert data["input_grms_g"] == pytest.approx(6.06, abs=0.01)  # the profile's own, as the standard quotes it


def test_two_dofs_against_a_direct_complex_solve(tmp_path):
    text = ('[time]\nend = 1.0\n[[mass]]\nname = "a"\nm = 2.0\n[[mass]]\nname = "b"\nm = 0.3\n[[spring]]\n'
            'connects = ["ground", "a"]\nk = 4.0e5\n[[spring]]\nconnects = ["a", "b"]\nk = 9.0e4\n[[damper]]\n'
            'connects = ["ground", "a"]\nc = 60.0\n[[damper]]\nconnects = ["a", "b"]\nc = 8.0\n')
    data = run(scene(tmp_path, text), "--input", PROFILE, "-o", tmp_path)
    M = np.diag([2.0, 0.3])
    K = np.array([[4.9e5, -9.0e4], [-9.0e4, 9.0e4]])
    C = np.array([[68.0, -8.0], [-8.0, 8.0]])
    w2, _ = np.linalg.eig(np.linalg.solve(M, K))
    natural = np.sqrt(np.sort(w2.real)) / (2 * math.pi)
    _, breaks = _profile(100.0)

    def x(f):
        w = 2 * math.pi * f
        return np.linalg.solve(K - w * w * M + 1j * w * C, -M @ np.ones(2))

    for j, name in enumerate(("a", "b")):
        total = 0.0
        for lo, hi in zip(breaks[:-1], breaks[1:]):
            inside = [f for f in natural if lo < f < hi]
            total += quad(lambda f: abs(x(f)[j]) ** 2 * _profile(f)[0], lo, hi, points=inside or None, epsabs=0,
                          epsrel=1e-12, limit=1000)[0]
        assert data["rms"]["displacement"][name] == pytest.approx(math.sqrt(total), rel=1e-6), name


def test_smd_psd_writes_the_file_and_plot(tmp_path):
    done = CliRunner().invoke(app, ["psd", str(SCENARIOS / "component_random_vibration.toml"), "--input",
                                    str(PROFILE), "-o", str(tmp_path)])
    assert done.exit_code == 0, done.output
    with h5py.File(tmp_path / "component_random_vibration_psd.h5") as f:
        assert f["response/acceleration"].shape[1] == 1 and f["rms/acceleration_g"].attrs["units"] == "g"
        f_hz, psd = f["frequency"][:], f["response/acceleration"][:, 0]
        rms = f["rms/acceleration"][0]
    # the written curve integrates to the RMS (the curve is dense across the resonance)
    assert math.sqrt(np.trapezoid(psd, f_hz)) == pytest.approx(rms, rel=2e-3)
    assert (tmp_path / "component_random_vibration_psd.png").stat().st_size > 20_000


@pytest.mark.parametrize("args, message", [
    (["--input", "white:-1"], "--input: expected a white-noise level > 0"),
    (["--input", "white:abc"], "--input: expected white:LEVEL with a number"),
    (["--input", "missing.csv"], "no such PSD profile"),
    (["--input", "white:0.1", "--on", "nobody"], "--on: expected a mass"),
    (["--input", "white:0.1", "--units", "N"], "--units: expected g or m/s^2"),
])
def test_bad_psd_options_exit_2(tmp_path, args, message):
    done = CliRunner().invoke(app, ["psd", str(SCENARIOS / "component_random_vibration.toml"), *args,
                                    "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and message in done.output and "Traceback" not in done.output
    assert not (tmp_path / "o").exists()


def test_a_response_that_overflows_is_refused(tmp_path):
    profile = tmp_path / "huge.csv"
    profile.write_text("10,1e307\n1000,1e307\n")  # over double precision once in (m/s^2)^2/Hz
    done = CliRunner().invoke(app, ["psd", str(SCENARIOS / "component_random_vibration.toml"), "--input",
                                    str(profile), "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and "overflow" in done.output and "Traceback" not in done.output
    profile.write_text("10,1e306\n1000,1e306\n")  # in range, but not the response
    done = CliRunner().invoke(app, ["psd", str(SCENARIOS / "component_random_vibration.toml"), "--input",
                                    str(profile), "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and "overflow" in done.output and "Traceback" not in done.output
    assert not (tmp_path / "o").exists()


def test_white_force_on_one_mass_of_two_against_quadrature(tmp_path):
    """The mass the force reaches directly has a white acceleration (infinite RMS, reported as null in JSON); the
    other's acceleration and both displacements are finite and equal the integral over all frequencies."""
    text = ('[time]\nend = 1.0\n[[mass]]\nname = "a"\nm = 2.0\n[[mass]]\nname = "b"\nm = 0.3\n[[spring]]\n'
            'connects = ["ground", "a"]\nk = 400.0\n[[spring]]\nconnects = ["a", "b"]\nk = 90.0\n[[damper]]\n'
            'connects = ["ground", "a"]\nc = 3.0\n[[damper]]\nconnects = ["a", "b"]\nc = 0.4\n')
    level = 2.0
    data = run(scene(tmp_path, text), "--input", f"white:{level}", "--on", "a", "-o", tmp_path)
    M = np.diag([2.0, 0.3])
    K = np.array([[490.0, -90.0], [-90.0, 90.0]])
    C = np.array([[3.4, -0.4], [-0.4, 0.4]])

    def x(f):
        w = 2 * math.pi * f
        return np.linalg.solve(K - w * w * M + 1j * w * C, np.array([1.0, 0.0]))

    natural = np.sqrt(np.sort(np.linalg.eigvals(np.linalg.solve(M, K)).real)) / (2 * math.pi)
    edges = [0.0, *natural, 10 * natural[-1], np.inf]

    def total(g):
        return sum(quad(g, lo, hi, epsabs=0, epsrel=1e-11, limit=2000)[0] for lo, hi in zip(edges[:-1], edges[1:]))

    assert data["rms"]["acceleration"]["a"] is None
    assert data["rms"]["displacement"]["a"] == pytest.approx(math.sqrt(level * total(lambda f: abs(x(f)[0]) ** 2)),
                                                             rel=1e-8)
    acc_b = total(lambda f: abs((2 * math.pi * f) ** 2 * x(f)[1]) ** 2)
    assert data["rms"]["acceleration"]["b"] == pytest.approx(math.sqrt(level * acc_b), rel=1e-8)
