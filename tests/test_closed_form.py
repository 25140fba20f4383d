"""closed_form, exact and a tight DOP853 agree in all four regimes and across zeta = 1."""

import numpy as np
import pytest
from conftest import model_of, one_dof

from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

TIGHT = Tolerances(rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("c, regime", [
    (0.0, "undamped"), (2.0, "underdamped"), (13.0, "overdamped"), (10.0, "critically damped"),
    (10.0 * (1 + 1e-9), None), (10.0 * (1 - 1e-9), None), (10.0 * (1 + 1e-4), "overdamped"),
])
def test_three_methods_agree(c, regime):
    _, model, grid = model_of(one_dof(c, x0=0.1, v0=-0.3))
    if regime:
        assert model.modes.regimes == (regime,)
    closed = solve(model, grid, "closed_form", Tolerances())
    exact = solve(model, grid, "exact", Tolerances())
    dop = solve(model, grid, "DOP853", TIGHT)
    np.testing.assert_allclose(closed.displacement, exact.displacement, rtol=0, atol=1e-14)
    np.testing.assert_allclose(closed.velocity, exact.velocity, rtol=0, atol=1e-13)
    np.testing.assert_allclose(closed.displacement, dop.displacement, rtol=0, atol=1e-11)
    np.testing.assert_allclose(closed.velocity, dop.velocity, rtol=0, atol=1e-10)


def test_continuous_across_critical_damping():
    """The response at zeta = 1 +- 1e-9 differs from zeta = 1 by O(1e-9), not by a formula switch."""
    responses = [solve(model_of(one_dof(c))[1], model_of(one_dof(c))[2], "closed_form", Tolerances()).displacement
                 for c in (10.0 * (1 - 1e-9), 10.0, 10.0 * (1 + 1e-9))]
    assert np.abs(responses[0] - responses[1]).max() < 1e-9
    assert np.abs(responses[2] - responses[1]).max() < 1e-9


def test_critical_matches_book_formula():
    """Equation (9-26): u = (A + B t) exp(-wn t), A = u0, B = v0 + wn u0."""
    _, model, grid = model_of(one_dof(10.0, x0=0.1, v0=0.0))
    x = solve(model, grid, "closed_form", Tolerances()).displacement[:, 0]
    wn = 5.0
    np.testing.assert_allclose(x, (0.1 + (0.0 + wn * 0.1) * grid) * np.exp(-wn * grid), rtol=1e-13, atol=1e-16)


def test_overdamped_long_run_does_not_overflow():
    """The linear twin of the book's stiff case, eigenvalues -1 and -1000, over 20 s."""
    _, model, grid = model_of(one_dof(1001.0, k=1000.0, x0=0.0, v0=1.0, end=20.0, step=0.01))
    x = solve(model, grid, "closed_form", Tolerances()).displacement[:, 0]
    exact = (np.exp(-grid) - np.exp(-1000 * grid)) / 999.0
    np.testing.assert_allclose(x, exact, rtol=1e-12, atol=1e-18)
