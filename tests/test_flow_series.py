"""The exact event-driven solver's shortcuts: a mode's flow as its Taylor polynomial (against the exponential of the
augmented matrix), and batches that go on past a guard's turn whose top stays below its level (against the run
that stops at every turn)."""

import numpy as np
import pytest
from conftest import SCENARIOS
from scipy.linalg import expm

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.solvers.events import piecewise
from smdcli.solvers.events.crossings import Crossings
from smdcli.solvers.exact.flow import NODES, SERIES_REACH, Flow


def random_mode(rng, n: int, exo: int):
    """A mode's A as modes.Scene builds it: a damped n-DOF structure driven by `exo` tables' (value, slope)
    generators, and a constant b."""
    s = 2 * n + 2 * exo
    A = np.zeros((s, s))
    K = rng.uniform(50, 400, (n, n))
    K = K @ K.T / n
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n] = -K
    A[n:2 * n, n:2 * n] = -0.05 * np.sqrt(np.diag(K)).max() * np.eye(n)
    for j in range(exo):
        lo = 2 * n + 2 * j
        A[lo, lo + 1] = 1.0
        A[n:2 * n, lo] = rng.normal(size=n)
    b = np.zeros(s)
    b[n:2 * n] = rng.normal(size=n)
    return A, b


def exact_at(A, b, z, tau):
    s = len(A)
    big = np.zeros((2 * s, 2 * s))
    big[:s, :s], big[:s, s:] = A, np.eye(s)
    full = expm(big * tau)
    return full[:s, :s] @ z + full[:s, s:] @ b


@pytest.mark.parametrize("n, exo", [(1, 1), (2, 1), (3, 2)])
def test_a_flows_taylor_polynomial_is_its_exponential_to_rounding(n, exo):
    """Steps of their own length (to an event), a guard's value along a step and the Gauss nodes' states from the
    Taylor polynomial: within 1e-13 of the exponential of the augmented matrix, up to omega h = SERIES_REACH; past
    it the polynomial is not offered."""
    rng = np.random.default_rng(n + 10 * exo)
    for _ in range(20):
        A, b = random_mode(rng, n, exo)
        flow = Flow(A)
        z = rng.normal(size=len(A)) * np.r_[np.full(n, 0.01), np.full(n, 0.1), np.ones(2 * exo)]
        h = rng.uniform(0.2, 1.0) * SERIES_REACH / flow.omega
        scale = np.abs(z).max() + np.abs(b).max() * h + np.abs(exact_at(A, b, z, h)).max()
        assert np.abs(flow.at(z, b, h) - exact_at(A, b, z, h)).max() <= 1e-13 * scale
        assert flow.state_series(z, b, h) is not None
        row, const = rng.normal(size=len(A)), float(rng.normal())
        along = flow.guard_polynomial(z, b, row, const, h)
        for tau in (0.0, 0.3 * h, h):
            expected = row @ exact_at(A, b, z, tau) + const
            assert abs(along(tau) - expected) <= 1e-13 * (np.abs(row) @ np.abs(z) + abs(const) + abs(expected))
        nodes = flow.gauss_states(z[None], b, h, keep=False)[0]
        for node, state in zip(NODES, nodes):
            assert np.abs(state - exact_at(A, b, z, node * h)).max() <= 1e-13 * scale
        far = 1.5 * SERIES_REACH / flow.omega
        assert flow.state_series(z, b, far) is None and flow.guard_polynomial(z, b, row, const, far) is None


def test_a_batch_goes_on_past_a_turn_whose_top_stays_below_the_yield_level(monkeypatch):
    """The bundled elastoplastic record: every oscillation peak below the yield level used to end a batch of output
    steps. The batches that go on past them find the same 42 events at the same times and the same motion as the run
    that stops at every turn and steps it alone, in under half the batches."""
    sc = scenario.load(SCENARIOS / "elastoplastic_record.toml")
    model, grid = build(sc), time_grid(sc.time)

    def counted(always_stop: bool):
        with monkeypatch.context() as patch:
            calls = []
            batch = piecewise.PiecewiseRun.batch
            patch.setattr(piecewise.PiecewiseRun, "batch", lambda self, *a: calls.append(1) or batch(self, *a))
            if always_stop:
                patch.setattr(Crossings, "turn_may_hold_event", lambda self, *a: True)
            run = piecewise.PiecewiseRun(model, grid)
            x, *_ = run.run()
            return x, sorted(run.events), len(calls)

    x, events, batches = counted(False)
    x_every, events_every, batches_every = counted(True)
    assert [(element, kind) for _, element, kind in events] == [(element, kind) for _, element, kind in events_every]
    assert len(events) == 42
    times, times_every = np.array([t for t, _, _ in events]), np.array([t for t, _, _ in events_every])
    assert np.abs(times - times_every).max() <= 1e-12 * grid[-1]
    assert np.abs(x - x_every).max() <= 1e-12 * np.abs(x_every).max()
    assert batches * 2 <= batches_every  # 129 against 290


def test_steps_by_doubling_are_the_steps_taken_one_by_one():
    """Flow.stepped (a product a doubling) against Flow.at taken step after step: 1,000 steps of a forced, damped
    oscillator, to 1e-12 of the largest state (the doubled powers' rounding against the steps')."""
    A = np.array([[0.0, 1.0], [-400.0, -2.0]])
    b = np.array([0.0, 3.0])
    flow = Flow(A)
    z = np.array([0.1, -0.5])
    want = [z]
    for _ in range(1000):
        want.append(flow.at(want[-1], b, 0.003, keep=True))
    got = flow.stepped(z, b, 0.003, 1000)
    want = np.array(want)
    assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
