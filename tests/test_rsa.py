"""`smd rsa`: response-spectrum analysis of a uniform 5-storey shear building against an independent eigen-solution
and the combination formulas written out here."""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
from conftest import ROOT, SCENARIOS
from typer.testing import CliRunner

from smdcli.cli import app

SCENE = SCENARIOS / "five_storey_building.toml"
DESIGN = ROOT / "records" / "design_spectrum_sds1_sd06.csv"
G = 9.80665
m, k, n = 45359.0, 5.5236e6, 5


def chain_matrices():
    M = m * np.eye(n)
    K = np.zeros((n, n))
    for i in range(n):
        K[i, i] += k
        if i > 0:
            K[i - 1, i - 1] += k
            K[i - 1, i] -= k
            K[i, i - 1] -= k
    return M, K


def independent_modes():
    """The uniform chain's modes from numpy's general eigen-solver of M^-1 K (not scipy's symmetric one), each
    shape mass-normalised."""
    M, K = chain_matrices()
    squared, shapes = np.linalg.eig(np.linalg.solve(M, K))
    order = np.argsort(squared.real)
    squared, shapes = squared.real[order], shapes.real[:, order]
    shapes = shapes / np.sqrt(np.einsum("im,ij,jm->m", shapes, M, shapes))
    shapes *= np.sign(shapes[-1])  # roof positive, as the file's sign is fixed: compare up to sign
    return np.sqrt(squared), shapes, M


def design_Sa(T):
    """The design table, read independently (linear in log period)."""
    table = np.loadtxt(DESIGN, delimiter=",", skiprows=1)
    return np.interp(np.log(T), np.log(table[:, 0]), table[:, 1]) * G


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("rsa")
    done = CliRunner().invoke(app, ["rsa", str(SCENE), "--spectrum", str(DESIGN), "-o", str(out), "--json"])
    assert done.exit_code == 0, done.output
    return json.loads(done.stdout), out / "five_storey_building_rsa.h5"


def test_periods_participation_and_effective_masses(result):
    data, h5 = result
    w, shapes, M = independent_modes()
    r = np.ones(n)
    gamma = shapes.T @ M @ r
    with h5py.File(h5) as f:
        period = f["modes/period"][:]
        participation = f["modes/participation"][:]
        effective = f["modes/effective_mass"][:]
        file_shapes = f["modes/shapes"][:]
    np.testing.assert_allclose(period, 2 * math.pi / w, rtol=1e-10)
    # the sign of a mode shape is a convention: compare Gamma phi, which is not
    sign = np.sign(file_shapes[-1])
    np.testing.assert_allclose(participation * sign, gamma, rtol=1e-10)
    np.testing.assert_allclose(effective, gamma**2, rtol=1e-10)
    assert abs(effective.sum() - n * m) < 1e-12 * n * m
    assert data["modes"][0]["period_s"] == pytest.approx(2.0, abs=1e-3)  # the textbook building's T1
    assert data["modes"][0]["cumulative_mass_ratio"] == pytest.approx(0.880, abs=1e-3)


def test_srss_and_cqc_equal_the_formulas(result):
    data, _ = result
    w, shapes, M = independent_modes()
    zeta = np.full(n, 0.05)
    gamma = shapes.T @ M @ np.ones(n)
    Sa = design_Sa(2 * math.pi / w)
    modal = (gamma * Sa / w**2)[:, None] * shapes.T  # (mode, dof)
    srss = np.sqrt((modal**2).sum(axis=0))
    cqc = np.zeros(n)
    for i in range(n):
        for j in range(n):
            b = w[j] / w[i]
            zi, zj = zeta[i], zeta[j]
            rho = (8 * math.sqrt(zi * zj) * (zi + b * zj) * b**1.5
                   / ((1 - b * b) ** 2 + 4 * zi * zj * b * (1 + b * b) + 4 * (zi * zi + zj * zj) * b * b))
            cqc += rho * modal[i] * modal[j]
    cqc = np.sqrt(cqc)
    names = ["floor1", "floor2", "floor3", "floor4", "roof"]
    got_srss = np.array([data["combined"]["srss"]["displacement_m"][d] for d in names])
    got_cqc = np.array([data["combined"]["cqc"]["displacement_m"][d] for d in names])
    got_abs = np.array([data["combined"]["abssum"]["displacement_m"][d] for d in names])
    np.testing.assert_allclose(got_srss, srss, rtol=1e-10)
    np.testing.assert_allclose(got_cqc, cqc, rtol=1e-10)
    np.testing.assert_allclose(got_abs, np.abs(modal).sum(axis=0), rtol=1e-10)
    # storey forces: k times the drift of each mode, combined; base shear: effective mass times Sa, combined
    drift = np.diff(np.concatenate([np.zeros((n, 1)), modal], axis=1), axis=1)
    storey = np.sqrt(((k * drift) ** 2).sum(axis=0))
    got = np.array([data["combined"]["srss"]["element_force_N"][f"spring[{i}]"] for i in range(n)])
    np.testing.assert_allclose(got, storey, rtol=1e-10)
    base = np.sqrt(((gamma**2 * Sa) ** 2).sum())
    assert data["combined"]["srss"]["base_shear_N"] == pytest.approx(base, rel=1e-10)
    # the first storey's force is the base shear mode by mode (nothing else reaches the ground)
    assert got[0] == pytest.approx(base, rel=1e-10)


def test_a_spectrum_file_of_smd_spectrum_is_a_source(tmp_path):
    """A single-DOF scene under the record's own spectrum: the RSA peak is Sd at its period and damping."""
    record = ROOT / "records" / "synthetic_20s_100hz.csv"
    runner = CliRunner()
    assert runner.invoke(app, ["spectrum", str(record), "--periods", "0.2:1:0.05", "--damping", "0.02,0.05,0.1",
                               "--no-plots", "-o", str(tmp_path)]).exit_code == 0
    scene = tmp_path / "one.toml"
    w = 2 * math.pi / 0.5
    scene.write_text(f'[time]\nend = 1.0\n[[mass]]\nname = "m"\nm = 1.0\n[[spring]]\nconnects = ["ground", "m"]\n'
                     f'k = {w * w!r}\n[[damper]]\nconnects = ["ground", "m"]\nc = {2 * 0.05 * w!r}\n')
    done = runner.invoke(app, ["rsa", str(scene), "--spectrum", str(tmp_path / "synthetic_20s_100hz_spectrum.h5"),
                               "-o", str(tmp_path), "--json", "--no-plots"])
    assert done.exit_code == 0, done.output
    with h5py.File(tmp_path / "synthetic_20s_100hz_spectrum.h5") as f:
        Sd = f["Sd"][1, list(np.round(f["period"][:], 6)).index(0.5)]
    assert json.loads(done.stdout)["combined"]["cqc"]["displacement_m"]["m"] == pytest.approx(Sd, rel=1e-10)


@pytest.mark.parametrize("args, message", [
    (["--combination", "max"], "--combination: expected one of cqc, srss, abssum"),
    (["--modes", "0"], "--modes: expected at least 1"),
    (["--modes", "few"], "--modes: expected a number of modes or all"),
])
def test_bad_rsa_options_exit_2(tmp_path, args, message):
    done = CliRunner().invoke(app, ["rsa", str(SCENE), "--spectrum", str(DESIGN), *args, "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and message in done.output and "Traceback" not in done.output
    assert not (tmp_path / "o").exists()


def test_a_spectrum_that_misses_a_period_is_refused(tmp_path):
    short = tmp_path / "short.csv"
    short.write_text("0.1, 1.0\n1.0, 0.6\n")
    done = CliRunner().invoke(app, ["rsa", str(SCENE), "--spectrum", str(short), "-o", str(tmp_path / "o")])
    assert done.exit_code == 2 and "outside the spectrum's periods" in done.output
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("combination", ["cqc", "srss"])
def test_the_chosen_combination_is_drawn_on_top_and_the_others_say_how_far(tmp_path, combination):
    """The plot's chosen rule is solid and above the others (CQC used to lie hidden under SRSS's markers, the two
    0.1 % apart); each other rule is drawn beneath with open markers, its label saying how far it is."""
    from smdcli.commands.rsa import rsa
    from smdcli.plots.rsa import rsa_figure

    run = rsa(SCENE, DESIGN, tmp_path, combination=combination, plots=False)
    peaks = rsa_figure(run).axes[1]
    lines = {line.get_label(): line for line in peaks.get_lines()}
    chosen = lines[f"{combination.upper()} (chosen)"]
    others = [line for label, line in lines.items() if "from" in label]
    assert len(others) == 2 and all(chosen.get_zorder() > line.get_zorder() for line in others)
    assert all(line.get_markerfacecolor() == "none" for line in others)
    for line in others:  # the stated distance is the drawn one
        stated = float(line.get_label().split("(")[1].split("%")[0]) / 100
        drawn = np.abs(line.get_xdata() - chosen.get_xdata()).max() / np.abs(chosen.get_xdata()).max()
        assert abs(stated - drawn) <= 0.0005 + 1e-12
