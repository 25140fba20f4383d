"""[damping]: Rayleigh damping by coefficients or through a ratio at two frequencies, and a damping ratio per
mode, against their defining formulas; the inputs it refuses."""

import json

import numpy as np
import pytest
from conftest import model_of, one_dof

# The book's three-DOF chain (SMDchain3.m) without its dampers: M = diag(2.5, 2, 3), springs 30, 5, 30, 60.
CHAIN = """
[time]
end = 2.0
step = 0.01
[[mass]]
name = "m1"
m = 2.5
x0 = 0.1
[[mass]]
name = "m2"
m = 2.0
[[mass]]
name = "m3"
m = 3.0
[[spring]]
connects = ["ground", "m1"]
k = 30.0
[[spring]]
connects = ["m1", "m2"]
k = 5.0
[[spring]]
connects = ["m2", "m3"]
k = 30.0
[[spring]]
connects = ["m3", "ground"]
k = 60.0
"""


def info(cli, tmp_path, text):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    result = cli("info", path, "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def undamped_frequencies(cli, tmp_path):
    return [mode["natural_frequency_rad_s"] for mode in info(cli, tmp_path, CHAIN)["modes"]]


def test_rayleigh_through_two_frequencies_gives_the_ratio_there_and_the_formula_between(cli, tmp_path):
    w = undamped_frequencies(cli, tmp_path)
    data = info(cli, tmp_path, CHAIN + f"[damping]\nzeta = 0.04\nomega = [{w[0]!r}, {w[2]!r}]\n")
    ratios = [mode["damping_ratio"] for mode in data["modes"]]
    assert ratios[0] == pytest.approx(0.04, abs=1e-12) and ratios[2] == pytest.approx(0.04, abs=1e-12)
    alpha, beta = 2 * 0.04 * w[0] * w[2] / (w[0] + w[2]), 2 * 0.04 / (w[0] + w[2])
    assert ratios[1] == pytest.approx(alpha / (2 * w[1]) + beta * w[1] / 2, rel=1e-12)
    assert ratios[1] < 0.04  # between the two frequencies a Rayleigh ratio dips
    assert [mode["natural_frequency_rad_s"] for mode in data["modes"]] == pytest.approx(w, rel=1e-12)


def test_rayleigh_coefficients_give_each_mode_alpha_over_2w_plus_beta_w_over_2(cli, tmp_path):
    w = np.array(undamped_frequencies(cli, tmp_path))
    data = info(cli, tmp_path, CHAIN + "[damping]\nalpha = 0.3\nbeta = 0.002\n")
    ratios = np.array([mode["damping_ratio"] for mode in data["modes"]])
    assert np.allclose(ratios, 0.3 / (2 * w) + 0.002 * w / 2, rtol=1e-12, atol=0)
    C = np.array(data["C"])
    assert np.allclose(C, 0.3 * np.diag([2.5, 2.0, 3.0]) + 0.002 * np.array(data["K"]), rtol=1e-15, atol=1e-15)


@pytest.mark.parametrize("modal, expected", [("0.02", [0.02] * 3), ("[0.02, 0.03, 0.05]", [0.02, 0.03, 0.05])])
def test_modal_damping_gives_each_mode_its_ratio(cli, tmp_path, modal, expected):
    data = info(cli, tmp_path, CHAIN + f"[damping]\nmodal = {modal}\n")
    assert [mode["damping_ratio"] for mode in data["modes"]] == pytest.approx(expected, abs=1e-12)


def test_modal_damping_on_one_dof_is_the_damper_it_stands_for():
    """zeta = 0.1 on m = 1, k = 25: the same motion as a damper c = 2 zeta sqrt(k m) = 1, to rounding."""
    from smdcli.solvers import solve
    from smdcli.solvers.base import Tolerances

    _, given, grid = model_of(one_dof(0.0) + "[damping]\nmodal = 0.1\n")
    _, damper, _ = model_of(one_dof(1.0))
    assert given.C[0, 0] == pytest.approx(1.0, rel=1e-15)
    a, b = (solve(m, grid, "auto", Tolerances()).displacement for m in (given, damper))
    assert np.abs(a - b).max() <= 1e-14


@pytest.mark.parametrize("table, message", [
    ("zeta = 0.05\nomega = [5.0, 5.0]", "two distinct positive frequencies"),
    ("zeta = 0.05\nomega = [-1.0, 5.0]", "two distinct positive frequencies"),
    ("zeta = 0.05\nomega = [1.0, 2.0, 3.0]", "damping.omega"),
    ("zeta = 0.05", "damping.omega: required with zeta"),
    ("omega = [1.0, 2.0]", "damping.zeta: required with omega"),
    ("alpha = 0.1\nmodal = 0.02", "one way of giving damping"),
    ("modal = [0.02, 0.03]", "damping.modal"),
    ("modal = -0.01", "damping.modal"),
    ("alpha = -5.0", "negatively damped"),
    ("alpha = 0.1\nbeta = -0.5", "negatively damped"),
    ("", "found an empty table"),
    ("alfa = 0.1", "alpha"),
])
def test_bad_damping_is_one_line_exit_2_and_writes_nothing(cli, tmp_path, table, message):
    path = tmp_path / "scene.toml"
    path.write_text(CHAIN + "[damping]\n" + table + "\n")
    result = cli("simulate", path, "-o", tmp_path / "out")
    assert result.exit_code == 2, result.output
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def _modal_c_40_digits(M, K, ratios):
    """Modal damping's C = L V diag(2 zeta_i w_i) V^T L (M = L L diagonal) at 40 digits (mpmath's eigensolver), as
    an mpmath matrix."""
    import mpmath as mp

    n = len(M)
    root = [mp.sqrt(M[i][i]) for i in range(n)]
    A = mp.matrix(n, n)
    for i in range(n):
        for j in range(n):
            A[i, j] = K[i][j] / (root[i] * root[j])
    values, vectors = mp.eigsy(A)
    order = sorted(range(n), key=lambda i: values[i])
    C = mp.matrix(n, n)
    for rank, mode in enumerate(order):
        f = 2 * ratios[rank] * mp.sqrt(values[mode])
        for i in range(n):
            for j in range(n):
                C[i, j] += root[i] * vectors[i, mode] * f * vectors[j, mode] * root[j]
    return C


@pytest.mark.parametrize("ratios", [(0.05,), (0.02, 0.05, 0.08), (0.1, 0.01, 0.04)])
def test_modal_damping_s_exact_derivative_matches_a_40_digit_difference(ratios):
    """d C / dp of modal damping (Daleckii and Krein's divided differences of 2 zeta sqrt(lambda) over the modes)
    where a mass and the stiffnesses move together, against a central difference over 1e-15 of p of C made at 40
    digits (its error 1e-30): to 1e-13 of the largest entry, within the rounding it states."""
    import mpmath as mp

    from smdcli.model.damping import modal_damping_derivative

    mp.mp.dps = 40
    sc, model, _ = model_of(CHAIN + f"[damping]\nmodal = {list(ratios) if len(ratios) > 1 else ratios[0]}\n")
    M, K = model.M, model.K
    dM = np.diag([0.0, 0.7, 0.0])
    dK = np.array([[3.0, -1.0, 0.0], [-1.0, 1.0, 2.0], [0.0, 2.0, -4.0]])
    slope, rounding = modal_damping_derivative(sc, M, K, dM, dK)
    every = np.broadcast_to(np.array(ratios), 3)
    h = mp.mpf("1e-15")
    at = lambda s: _modal_c_40_digits([[mp.mpf(M[i, j]) + s * dM[i, j] for j in range(3)] for i in range(3)],  # noqa
                                      [[mp.mpf(K[i, j]) + s * dK[i, j] for j in range(3)] for i in range(3)],
                                      [mp.mpf(r) for r in every])
    want = np.array(((at(h) - at(-h)) / (2 * h)).tolist(), dtype=float)
    error = np.abs(slope - want).max() / np.abs(want).max()
    assert error <= 1e-13 and error <= 10 * rounding, (error, rounding)


def test_modal_damping_s_derivative_is_refused_where_it_does_not_exist():
    """None (the sensitivity takes its stencil, which states how good it is) where C has no derivative of this form:
    a free mode (sqrt(lambda) has no slope at zero), two modes of different ratios at one frequency, a full M."""
    from smdcli.model.damping import modal_damping_derivative

    sc, model, _ = model_of(CHAIN + "[damping]\nmodal = [0.02, 0.05, 0.08]\n")
    dM, dK = np.zeros((3, 3)), np.eye(3)
    assert modal_damping_derivative(sc, model.M, model.K, dM, dK) is not None
    free = np.array([[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
    assert modal_damping_derivative(sc, np.eye(3), free, dM, dK) is None
    assert modal_damping_derivative(sc, np.eye(3), np.diag([4.0, 4.0, 9.0]), dM, dK) is None
    full = np.eye(3) + 0.1 * (np.ones((3, 3)) - np.eye(3))
    assert modal_damping_derivative(sc, full, model.K, dM, dK) is None
    sc, _, _ = model_of(CHAIN + "[damping]\nmodal = 0.05\n")  # one ratio: repeated modes have a derivative
    assert modal_damping_derivative(sc, np.eye(3), np.diag([4.0, 4.0, 9.0]), dM, dK) is not None
