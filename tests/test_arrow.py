"""The sensitivity system's flow by its arrow structure (solvers/exact/arrow.py) against independent references: the
complex step of a chain's state transition written here from its matrices, scipy's expm of the assembled arrow, the
stacked system's dense powers, and the sparse action's own cost estimate."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import smdcli
from smdcli.analysis.model_derivative import augmented_model, model_derivatives
from smdcli.solvers.exact import linear
from smdcli.solvers.exact.action import Action, action_cost, dense_action_cost
from smdcli.solvers.exact.accurate_expm import flush_negligible
from smdcli.solvers.exact.arrow import Arrow, ArrowFlow, arrow_expm, arrow_form
from conftest import model_of

H = 1e-30  # the complex step


def chain_text(n: int) -> str:
    """An n-mass chain fixed at one end (1 kg, 100 N/m), a 0.5 N s/m damper at the free end only (no classical
    damping: no modal path), 10 s at 0.01 s, a 10 N sine at 5 rad/s on the first mass, the last mass moved 1 mm."""
    lines = ["[time]", "end = 10.0", "step = 0.01"]
    for i in range(n):
        lines += ["[[mass]]", f'name = "m{i}"', "m = 1.0"] + (["x0 = 0.001"] if i == n - 1 else [])
    for i in range(n):
        lines += ["[[spring]]", f'connects = ["{"ground" if i == 0 else f"m{i - 1}"}", "m{i}"]', "k = 100.0"]
    lines += ["[[damper]]", f'connects = ["m{n - 2}", "m{n - 1}"]', "c = 0.5"]
    lines += ["[[force]]", 'on = "m0"', 'type = "sine"', "amplitude = 10.0", "omega = 5.0"]
    return "\n".join(lines) + "\n"


def chain_matrices(n: int, k0, c, m1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """chain_text(n)'s M, K and C, written here (complex: an argument may carry the complex step)."""
    M = np.eye(n, dtype=complex)
    M[1, 1] = m1
    K = np.zeros((n, n), complex)
    for i in range(n):
        k = k0 if i == 0 else 100.0
        K[i, i] += k
        if i:
            K[i - 1, i - 1] += k
            K[i - 1, i] -= k
            K[i, i - 1] -= k
    C = np.zeros((n, n), complex)
    C[n - 2:, n - 2:] = c * np.array([[1, -1], [-1, 1]])
    return M, K, C


def chain_reference(n: int, k0=100.0, c=0.5, m1=1.0) -> np.ndarray:
    """chain_text(n)'s (x, v, a) on its grid (1,001, 3n) by the state transition of its matrices written here (the
    force's [sin, cos] as exosystem), every argument possibly complex."""
    M, K, C = chain_matrices(n, k0, c, m1)
    Minv = np.linalg.inv(M)
    A = np.zeros((2 * n + 2, 2 * n + 2), complex)
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n], A[n:2 * n, n:2 * n] = -Minv @ K, -Minv @ C
    A[n:2 * n, 2 * n] = Minv[:, 0] * 10.0
    A[2 * n, 2 * n + 1], A[2 * n + 1, 2 * n] = 5.0, -5.0  # [sin 5t, cos 5t]
    z = np.zeros(2 * n + 2, complex)
    z[n - 1], z[2 * n + 1] = 0.001, 1.0
    step = scipy.linalg.expm(A * 0.01)
    out = np.empty((1001, 2 * n + 2), complex)
    out[0] = z
    for i in range(1000):
        out[i + 1] = z = step @ z
    accelerations = out @ A[n:2 * n].T
    return np.concatenate([out[:, :2 * n], accelerations], axis=1)


@pytest.mark.slow
def test_a_long_chain_s_sensitivities_take_the_arrow_and_match_the_complex_step(monkeypatch):
    """A 40-mass chain damped at its end, three parameters (a spring, the damper, a mass): the arrow's flow is taken
    (cheaper than the stacked system's dense exponential and sparse action) and each sensitivity matches the complex
    step of the chain's state transition to 1e-10 of its largest in x, v and a, within the accuracy it states."""
    taken = []
    original = ArrowFlow.of.__func__
    monkeypatch.setattr(ArrowFlow, "of", classmethod(lambda cls, *a: taken.append(original(cls, *a)) or taken[-1]))
    n = 40
    sc, _, _ = model_of(chain_text(n), "chain.toml")
    params = {"spring[0].k": {"k0": 100 + 1j * H}, "damper[0].c": {"c": 0.5 + 1j * H}, "mass.m1.m": {"m1": 1 + 1j * H}}
    s = smdcli.sensitivity(sc, list(params))
    assert taken and taken[-1] is not None
    nominal = chain_reference(n).real
    for q, quantity in enumerate(("displacement", "velocity", "acceleration")):
        want = nominal[:, q * n:(q + 1) * n]
        assert np.abs(getattr(s, quantity) - want).max() <= 1e-12 * np.abs(want).max(), quantity
    for i, arguments in enumerate(params.values()):
        reference = chain_reference(n, **arguments).imag / H
        for q, quantity in enumerate(("displacement", "velocity", "acceleration")):
            want = reference[:, q * n:(q + 1) * n]
            error = np.abs(getattr(s, f"d_{quantity}")[i] - want).max() / np.abs(want).max()
            assert error <= 1e-10, (s.parameter[i], quantity, error)
            assert error <= s.accuracy[f"d_{quantity}"][i], (s.parameter[i], quantity, error)


def record_chain_reference(n: int, record: np.ndarray, k0=100.0, m1=1.0) -> np.ndarray:
    """chain_text(n)'s chain at rest, driven by a ground acceleration sampled every 0.01 s (its first-order hold, as
    smd's table is) instead of its force: relative (x, v) on the grid (1,001, 2n) by the state transition written
    here, the record's [value, slope] reseeded at every sample; every argument possibly complex."""
    M, K, C = chain_matrices(n, k0, 0.5, m1)
    Minv = np.linalg.inv(M)
    A = np.zeros((2 * n + 2, 2 * n + 2), complex)
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n], A[n:2 * n, n:2 * n] = -Minv @ K, -Minv @ C
    A[n:2 * n, 2 * n] = -np.ones(n)  # M^-1 (-M 1 a_g)
    A[2 * n, 2 * n + 1] = 1.0  # a_g' = its slope
    step = scipy.linalg.expm(A * 0.01)
    z = np.zeros(2 * n + 2, complex)
    out = np.empty((1001, 2 * n), complex)
    out[0] = z[:2 * n]
    for i in range(1000):
        z[2 * n], z[2 * n + 1] = record[i], (record[i + 1] - record[i]) / 0.01
        z = step @ z
        out[i + 1] = z[:2 * n]
    return out


@pytest.mark.slow
def test_a_chain_under_a_record_steps_its_copies_by_the_arrow_and_matches_the_complex_step(monkeypatch):
    """The same chain (40 masses, damped at its end) under a ground acceleration sampled at its output step, two
    parameters: the record's recurrence runs the scene, then both copies at once by the arrow's blocks, and each
    sensitivity matches the complex step of the chain's state transition to 1e-10 of its largest in x and v, within
    the accuracy it states."""
    from smdcli.solvers.exact import arrow

    taken = []
    monkeypatch.setattr(linear, "arrow_sampled_states",
                        lambda *a: taken.append(arrow.arrow_sampled_states(*a)) or taken[-1])
    n = 40
    record = np.round(np.random.default_rng(5).standard_normal(1001), 4)
    text = chain_text(n).split("[[force]]")[0].replace("x0 = 0.001\n", "")
    text += (f'[ground_motion]\nquantity = "acceleration"\ntype = "table"\n'
             f't = [{", ".join(f"{t:.2f}" for t in np.arange(1001) * 0.01)}]\n'
             f'values = [{", ".join(repr(float(v)) for v in record)}]\n')
    sc, _, _ = model_of(text, "record.toml")
    params = {"spring[0].k": {"k0": 100 + 1j * H}, "mass.m1.m": {"m1": 1 + 1j * H}}
    s = smdcli.sensitivity(sc, list(params))
    assert taken and taken[-1] is not None
    nominal = record_chain_reference(n, record).real
    assert np.abs(s.displacement - nominal[:, :n]).max() <= 1e-12 * np.abs(nominal[:, :n]).max()
    for i, arguments in enumerate(params.values()):
        reference = record_chain_reference(n, record, **arguments).imag / H
        for q, quantity in enumerate(("displacement", "velocity")):
            want = reference[:, q * n:(q + 1) * n]
            error = np.abs(getattr(s, f"d_{quantity}")[i] - want).max() / np.abs(want).max()
            assert error <= 1e-10, (s.parameter[i], quantity, error)
            assert error <= s.accuracy[f"d_{quantity}"][i], (s.parameter[i], quantity, error)


def random_arrow(rng, q: int, lead: int, copies: int, norm: float) -> tuple[np.ndarray, np.ndarray]:
    """A_w (q, q) block upper triangular ([[A, G], [0, S]], A lead x lead) and B (copies, lead, q), scaled so that
    the assembled arrow's 1-norm is `norm`."""
    A_w = rng.standard_normal((q, q))
    A_w[lead:, :lead] = 0.0
    B = rng.standard_normal((copies, lead, q))
    whole = Arrow(A_w, B).dense()
    by = norm / np.abs(whole).sum(axis=0).max()
    return A_w * by, B * by


@pytest.mark.parametrize("norm", [0.01, 1.0, 5.0, 15.0])
def test_the_arrow_s_exponential_is_scipy_s_of_the_assembled_matrix(norm):
    """exp(Z t) of random arrows (two copies, a generator block), from below Pade 13's reach to three squarings,
    within 1e-14 of its largest entry of scipy's expm of the assembled matrix; past NEEDED_NORM it is declined."""
    rng = np.random.default_rng(7)
    A_w, B = random_arrow(rng, 14, 10, 2, norm)
    found, measured = arrow_expm(A_w, B, 1.0)
    assert measured == pytest.approx(norm, rel=1e-12)
    want = scipy.linalg.expm(Arrow(A_w, B).dense())
    assert np.abs(found.dense() - want).max() <= 1e-14 * np.abs(want).max()
    assert arrow_expm(A_w, B, 20.0 / norm) is None


def stacked_of(n: int, params: list[str]):
    """(stacked model, grid) of chain_text(n)'s sensitivity system."""
    sc, base, grid = model_of(chain_text(n), "chain.toml")
    stacked, _ = augmented_model(base, model_derivatives(sc, base, grid, params, None, flowed=True))
    return stacked, grid


def test_the_stacked_sensitivity_system_is_an_arrow_and_its_tables_are_its_powers():
    """The stacked system of a chain's two parameters is the arrow (each copy the scene's own matrix, reaching
    nothing but the scene); the rows read over J steps by doubling equal the rows times the assembled step's powers
    (1e-13 of the largest), a block's start by the J-th power equals J single steps, and a scene-only row reaches
    no copy."""
    n = 6
    stacked, grid = stacked_of(n, ["spring[0].k", "mass.m1.m"])
    Aaug, _ = linear.augmented(stacked)
    order, A_w, B = arrow_form(Aaug, n, 2)
    assert np.array_equal(Aaug[np.ix_(order, order)], Arrow(A_w, B).dense())
    flow = ArrowFlow.of(Aaug, n, 2, 0.01, len(grid), 30)
    step = scipy.linalg.expm(Aaug[np.ix_(order, order)] * 0.01)
    rows = np.zeros((3, len(Aaug)))  # in the arrow's order: [x, v and the force's generator of the scene; copies]
    rows[0, 0], rows[1, n + 1], rows[2, len(order) - 1] = 1.0, 1.0, 1.0  # the scene's x and v, copy 2's last v
    rows[2, 3] = 0.5  # and the scene's x on that row
    tables = flow.tables(rows)
    power = np.eye(len(Aaug))
    for j in range(flow.J):
        power = power @ step
        assert np.abs(tables[j] - rows @ power).max() <= 1e-13 * np.abs(rows @ power).max(), j
    assert not tables[:, :2, len(A_w):].any()  # the scene's rows reach no copy
    z = np.random.default_rng(3).standard_normal(len(Aaug))
    stepped = z
    for _ in range(flow.J):
        stepped = flow.step(stepped, 1)
    assert np.abs(flow.step(z, flow.J) - stepped).max() <= 1e-13 * np.abs(stepped).max()


def test_a_stacked_system_that_is_not_an_arrow_is_declined():
    """A copy reaching another copy is not the arrow: arrow_form declines it (the dense path takes the system)."""
    n = 4
    stacked, _ = stacked_of(n, ["spring[0].k", "mass.m1.m"])
    Aaug, _ = linear.augmented(stacked)
    assert arrow_form(Aaug, n, 2) is not None
    coupled = Aaug.copy()
    coupled[n, 2 * n] = 1.0  # copy 1's x driven by copy 2's (z: the three blocks' x, then their v)
    assert arrow_form(coupled, n, 2) is None
    other = Aaug.copy()
    other[n, n] = 1.0  # copy 1 not the scene's own matrix
    assert arrow_form(other, n, 2) is None


def test_the_sparse_action_s_cost_is_estimated_without_building_it():
    """dense_action_cost, from the augmented matrix alone, is action_cost of the built Action (the same balanced,
    shifted norm and entries) on a stacked chain of 64 DOFs and more."""
    stacked, grid = stacked_of(40, ["spring[0].k", "mass.m1.m"])
    Aaug, _ = linear.augmented(stacked)
    want = action_cost(Action(stacked), stacked, grid)
    assert dense_action_cost(Aaug, stacked.n, stacked, grid) == pytest.approx(want, rel=1e-9)


def test_negligible_entries_are_flushed_and_the_rest_kept():
    """Entries below 2^-400 of the largest (and subnormal ones) become zero; the rest are kept bit for bit."""
    array = np.array([3.0, 1e-125, -2e-120, 5e-310, 0.0, -4.0])
    kept = array.copy()
    flush_negligible(array)
    assert array.tolist() == [3.0, 0.0, kept[2], 0.0, 0.0, -4.0]
