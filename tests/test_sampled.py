"""Linear scenes driven by tables on one uniform grid of knots (smdcli.solvers.exact.sampled): the record's double
integral against exact rational arithmetic, and every case against the dense path's per-breakpoint steps."""

from fractions import Fraction

import numpy as np
import pytest
from conftest import SCENARIOS, model_of

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.shapes.registry import Constant, FourierSquare, Harmonic, Pulse, Square, Step
from smdcli.shapes.table import Table
from smdcli.solvers import ground, solve
from smdcli.solvers.exact import sampled
from smdcli.solvers.base import Tolerances

SAMPLED = "steps between the tables' samples"


def three_dof(tables: str, end: float = 2.0, step: float = 0.01) -> str:
    return f"""
[time]
end = {end!r}
step = {step!r}
[[mass]]
name = "a"
m = 2.0
x0 = 0.01
[[mass]]
name = "b"
m = 1.0
[[mass]]
name = "c"
m = 0.5
v0 = -0.2
[[spring]]
connects = ["ground", "a"]
k = 400.0
[[spring]]
connects = ["a", "b"]
k = 250.0
[[spring]]
connects = ["b", "c"]
k = 900.0
[[damper]]
connects = ["ground", "a"]
c = 1.5
[[damper]]
connects = ["b", "c"]
c = 0.3
{tables}"""


def table(on: str, times, values, interpolation: str = "linear") -> str:
    return (f'[[force]]\non = "{on}"\ntype = "table"\ninterpolation = "{interpolation}"\n'
            f"t = {[float(t) for t in times]!r}\nvalues = {[float(v) for v in values]!r}\n")


def dense(model, grid, monkeypatch):
    """The same scene by the dense path, which reseeds the tables at every breakpoint."""
    with monkeypatch.context() as patch:
        patch.setattr(sampled, "uniform_knots", lambda model, grid: None)
        result = solve(model, grid, "exact", Tolerances())
    assert SAMPLED not in result.stats.message
    return result


def assert_agree(fast, slow):
    assert SAMPLED in fast.stats.message
    for name in ("displacement", "velocity", "acceleration"):
        a, b = getattr(fast, name), getattr(slow, name)
        gap = np.abs(a - b).max() / np.abs(b).max()
        assert gap <= fast.stats.stated_accuracy + slow.stats.stated_accuracy, (name, gap)


def test_a_records_double_integral_is_exact_rational_arithmetics_to_its_stated_accuracy():
    """The ground's displacement and velocity from the bundled record's accelerations (first-order hold, 2,001
    samples): against the same integrals in exact fractions of the samples, within the path's stated accuracy
    (itself 1.9e-12, rounding's bound for 2,000 steps); the dense path it replaces left 2.3e-14 there, this one
    9.9e-15."""
    sc = scenario.load(SCENARIOS / "shear_frame_record.toml")
    model, grid = build(sc), time_grid(sc.time)
    g = model.ground
    times = [Fraction(float(t)) for t in grid]
    accelerations = [Fraction(float(a)) for a in g.acceleration.value(grid)]
    u, v = [Fraction(g.u0)], [Fraction(g.v0)]
    for k in range(len(grid) - 1):
        h, a0, a1 = times[k + 1] - times[k], accelerations[k], accelerations[k + 1]
        u.append(u[-1] + h * v[-1] + h * h * (2 * a0 + a1) / 6)
        v.append(v[-1] + h * (a0 + a1) / 2)
    history = ground.ground_history(model, grid, solve)
    assert 0 < history.integrated_accuracy <= 1e-11
    for found, exact in ((history.displacement, u), (history.velocity, v)):
        exact = np.array([float(x) for x in exact])
        assert np.abs(found - exact).max() / np.abs(exact).max() <= history.integrated_accuracy


@pytest.mark.parametrize("case", ["on the output points", "twice as fine", "an ulp after the output points",
                                  "an ulp before the output points", "coarser, previous value"])
def test_tables_on_one_uniform_grid_agree_with_the_dense_paths_steps(case, monkeypatch):
    """Three masses, a first-order hold and a previous-value table together: the blocks of steps against the dense
    path, which steps from breakpoint to breakpoint, within their stated accuracies. Samples within an ulp of the
    output points are read on their own side: read at the output point, a previous-value table's jump would come
    one step late (a gap of about 1e-3 of the peak)."""
    rng = np.random.default_rng(7)
    grid_times = np.round(np.arange(0, 201) * 0.01, 12)
    times = {"on the output points": grid_times, "twice as fine": np.round(np.arange(0, 401) * 0.005, 12),
             "an ulp after the output points": np.nextafter(grid_times, np.inf),
             "an ulp before the output points": np.nextafter(grid_times, -np.inf),
             "coarser, previous value": np.round(np.arange(0, 41) * 0.05, 12)}[case]
    times[0] = 0.0
    values = rng.normal(size=len(times)) * 20
    steps = rng.normal(size=len(times)) * 5
    text = three_dof(table("a", times, values) + table("c", times, steps, "previous"))
    _, model, grid = model_of(text)
    fast = solve(model, grid, "auto", Tolerances())
    assert fast.stats.method == "exact"
    assert_agree(fast, dense(model, grid, monkeypatch))


def test_samples_off_the_uniform_grid_take_the_dense_path():
    """Samples at uneven times: no uniform grid of knots, so the dense path steps from sample to sample."""
    times = [0.0, 0.013, 0.4, 0.77, 1.5, 2.0]
    _, model, grid = model_of(three_dof(table("b", times, [0.0, 3.0, -2.0, 5.0, 1.0, 0.0])))
    assert sampled.uniform_knots(model, grid) is None
    result = solve(model, grid, "exact", Tolerances())
    assert SAMPLED not in result.stats.message and "force segment" in result.stats.message


@pytest.mark.parametrize("interpolation", ["linear", "previous"])
def test_a_tables_states_at_many_times_are_its_states_at_each(interpolation):
    """exo_states (value, slope) equals exo_state at each time: before the first sample, at and between samples,
    past the last."""
    signal = Table([0.5, 1.0, 1.25, 3.0], [2.0, -1.0, 4.0, 0.5], interpolation)
    times = np.array([0.0, 0.5, 0.7, 1.0, 1.1, 1.25, 2.0, 3.0, 3.5])
    expected = np.array([signal.exo_state(float(t)) for t in times])
    np.testing.assert_array_equal(signal.exo_states(times), expected)


@pytest.mark.parametrize("signal", [Harmonic(2.0, 7.0, 0.3, False), Harmonic(2.0, 7.0, 0.3, True), Step(1.5, 1.25),
                                    Constant(-4.0), FourierSquare(1.0, 3.0, 5, 0.2), Square(1.0, 3.0, 0.3, 0.2),
                                    Pulse(0.5, 2.0, 1.0, 2.0, 3, 0)])
def test_every_generator_s_states_at_many_times_are_its_states_at_each(signal):
    """exo_states at many times (vectorized where the shape has it: the exact solver reseeds every block's start and
    the event batches every step with them) equals exo_state at each: at and around a step's or a pulse's edge and
    over late times, to an ulp of numpy's sin and cos against the math module's."""
    times = np.array([0.0, 0.1999999, 0.2, 0.5, 1.25 - 1e-12, 1.25, 1.7, 2.0, 3.3, 1234.5678])
    expected = np.array([signal.exo_state(float(t)) for t in times]).reshape(len(times), -1)
    np.testing.assert_allclose(signal.exo_states(times), expected, rtol=0, atol=4 * np.finfo(float).eps)


def test_a_large_classically_damped_chain_under_a_record_steps_its_modes_in_blocks(monkeypatch, tmp_path):
    """100 masses, damping proportional to stiffness, a ground acceleration record sampled twice as finely as the
    output: every mode's steps in blocks against the modal path's step-by-step walk, within their stated accuracies,
    in chunks of a few steps as in one (a chunk's end state carried to the next)."""
    from smdcli.solvers.exact import modal

    rng = np.random.default_rng(3)
    record = tmp_path / "record.csv"
    times = np.round(np.arange(0, 801) * 0.005, 12)
    record.write_text("".join(f"{float(t)!r},{float(a)!r}\n" for t, a in zip(times, rng.normal(size=len(times)))))
    lines = ["[time]", "end = 4.0", "step = 0.01"]
    for i in range(100):
        lines += ["[[mass]]", f'name = "m{i}"', f"m = {1.0 + 0.01 * i!r}"]
    for i in range(100):
        left = "ground" if i == 0 else f"m{i - 1}"
        lines += ["[[spring]]", f'connects = ["{left}", "m{i}"]', "k = 2000.0",
                  "[[damper]]", f'connects = ["{left}", "m{i}"]', "c = 0.4"]
    lines += ["[ground_motion]", 'quantity = "acceleration"', 'type = "table"', f'file = "{record}"', 'units = "g"']
    _, model, grid = model_of("\n".join(lines) + "\n")
    assert modal.modal_applies(model)
    fast = solve(model, grid, "exact", Tolerances())
    assert SAMPLED in fast.stats.message and "modal coordinates" in fast.stats.message
    assert_agree(fast, dense(model, grid, monkeypatch))
    monkeypatch.setattr(sampled, "CHUNK_ENTRIES", 2000)  # one block of 64 steps a chunk: 13 chunks
    chunked = solve(model, grid, "exact", Tolerances())
    assert np.abs(chunked.displacement - fast.displacement).max() <= 1e-14 * np.abs(fast.displacement).max()


def test_units_are_not_stiffness_a_balanced_exponential_matches_40_digits(tmp_path):
    """Two 1,000 kg masses on 4e6 N/m springs under a record: ||A h||_1 = 120 from the units (the squared frequency
    times h), 1.3 once balanced, so the exponential is taken in double, not double-double. Against the same steps
    in 40-digit arithmetic (mpmath's exponential, the tables reseeded at every sample): within 1e-13 of the peak
    (4.1e-15 measured; over 10 s, 8.4e-15 where double-double left 2.1e-15) and within the stated accuracy (5.0e-13)."""
    import mpmath as mp

    from smdcli.solvers.exact.linear import augmented

    rng = np.random.default_rng(11)
    record = tmp_path / "record.csv"
    times = np.round(np.arange(0, 301) * 0.01, 12)
    record.write_text("".join(f"{float(t)!r},{float(a)!r}\n" for t, a in zip(times, rng.normal(size=len(times)))))
    text = f"""
[time]
end = 3.0
step = 0.01
[[mass]]
name = "a"
m = 1000.0
[[mass]]
name = "b"
m = 1000.0
[[spring]]
connects = ["ground", "a"]
k = 4e6
[[spring]]
connects = ["a", "b"]
k = 4e6
[[damper]]
connects = ["ground", "a"]
c = 2000.0
[ground_motion]
quantity = "acceleration"
type = "table"
file = "{record}"
units = "g"
"""
    _, model, grid = model_of(text)
    Aaug, blocks = augmented(model)
    assert np.abs(Aaug).sum(axis=0).max() * 0.01 > 100
    result = solve(model, grid, "exact", Tolerances())
    assert SAMPLED in result.stats.message and "double-double" not in result.stats.message
    with mp.workdps(40):
        step = mp.expm(mp.matrix(Aaug.tolist()) * mp.mpf(0.01))
        z = mp.matrix([0] * len(Aaug))
        reference = [[0.0, 0.0]]
        for t in grid[:-1]:
            for lo, hi, signal in blocks:
                for i, value in enumerate(signal.exo_state(float(t))):
                    z[lo + i] = mp.mpf(float(value))
            z = step * z
            reference.append([float(z[0]), float(z[1])])
    reference = np.array(reference)
    error = np.abs(result.displacement - reference).max() / np.abs(reference).max()
    assert error <= 1e-13 and error <= result.stats.stated_accuracy, error


@pytest.mark.parametrize("systems", [1, 3])
@pytest.mark.parametrize("shared", [True, False])
def test_the_blocked_recurrence_is_the_step_by_step_one(systems, shared, monkeypatch):
    # y_(k+1) = E y_k + f_k taken one step at a time, against the blocks: chunks of a few blocks (the chunk's end
    # carried to the next), every step wanted and only some, E one for all systems or one each
    monkeypatch.setattr(sampled, "CHUNK_ENTRIES", 3 * 64 * 4 * systems)
    rng = np.random.default_rng(7)
    E = rng.normal(size=(1 if shared else systems, 4, 4)) * 0.45
    steps = 1024  # whole blocks: the last output is the last block's end, not one of its steps
    forced, start = rng.normal(size=(steps, systems, 4)), rng.normal(size=(systems, 4))
    y, want = start.copy(), [start.copy()]
    for k in range(steps):
        y = np.einsum("pij,pj->pi", np.broadcast_to(E, (systems, 4, 4)), y) + forced[k]
        want.append(y.copy())
    want = np.array(want)
    for rows in (np.arange(steps + 1), np.array([0, 5, 191, 192, 193, 640, 999, 1024]), np.array([1024])):
        got, _ = sampled.recurrence(E, forced, start, rows)
        # each block's rounding against the plain loop's: a few hundred products of norm below 2
        assert np.abs(got - want[rows]).max() <= 1e-12 * np.abs(want).max()


def test_restarted_steps_are_the_steps_taken_one_by_one():
    """reseeded_steps (a record's generators restarted after every step, the rest one recurrence driven by them)
    against the same flow stepped and restarted one step at a time: 300 steps of a damped 2-DOF scene with two
    generator entries, to 1e-13 of the largest state (each path's rounding over the run)."""
    from scipy.linalg import expm

    rng = np.random.default_rng(7)
    A = np.zeros((6, 6))
    A[:2, 2:4] = np.eye(2)
    A[2:4, :2] = [[-40.0, 10.0], [10.0, -25.0]]
    A[2:4, 2:4] = [[-0.3, 0.1], [0.1, -0.2]]
    A[2:4, 4:] = rng.normal(size=(2, 2))  # the generators drive the velocities
    A[4, 5] = 1.0  # a value and its slope: a first-order hold's generator
    E = expm(A * 0.01)
    shift = rng.normal(size=6) * 1e-3
    shift[4:] = 0.0
    restarted = np.array([4, 5])
    seeds = rng.normal(size=(300, 2))
    start = rng.normal(size=6)
    want = [start]
    for seed in seeds:
        z = E @ want[-1] + shift
        z[restarted] = seed
        want.append(z)
    got = sampled.reseeded_steps(E, shift, start, seeds, restarted)
    want = np.array(want)
    assert np.abs(got - want).max() <= 1e-13 * np.abs(want).max()
