"""The compiled Taylor series (method 'taylor', auto's choice for smooth nonlinear scenes) against independent
references: scipy's DOP853 and smd's Radau at tight tolerances, the exact modal solution of a linear scene, the
equilibrium of the model's own right-hand side, and the stability limit of the truncated exponential."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import bundled as load
from conftest import model_of
from test_kernels import FORCES

from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances
from smdcli.solvers.integrators.taylor_series import taylor_boundary, taylor_order
from smdcli.solvers.registry import solver_class

Taylor = solver_class("taylor")

TIGHT = Tolerances(rtol=1e-13, atol=1e-16)


def smooth_forces() -> str:
    """test_kernels' scene with every force kind but those with no series (chirp, expression)."""
    head, *blocks = FORCES.split("[[force]]")
    kept = [b for b in blocks if 'type = "chirp"' not in b and 'type = "expression"' not in b]
    return "[[force]]".join([head, *kept])


def relative_error(result, reference) -> float:
    peak = np.abs(reference.displacement).max()
    return float(np.abs(result.displacement - reference.displacement).max() / peak)


@pytest.mark.parametrize("rtol", [1e-6, 1e-8, 1e-10])
def test_every_force_with_a_series_and_both_element_laws_within_rtol_of_a_tight_dop853(rtol):
    """Constant, step, pulse, sine, cosine, square, Fourier square and both tables, on a cubic spring and a quadratic
    damper, restarted at each edge: the error stays under the tolerance asked for."""
    _, model, grid = model_of(smooth_forces())
    assert Taylor().refuse(model) is None
    ours = solve(model, grid, "taylor", Tolerances(rtol=rtol, atol=1e-12))
    reference = solve(model, grid, "scipy:DOP853", TIGHT)
    assert ours.success, ours.stats.message
    assert relative_error(ours, reference) <= rtol
    assert ours.stats.steps_rejected == 0


def test_the_books_stiff_damper_at_its_settings_is_within_1e_9_of_a_tight_radau_in_fewer_terms_than_dop853_stages():
    """The book's c |v| v scene reverses 200 times: each reversal is a root of the velocity's series, where a step
    ends, so the series never spans the kink; its default run is 20x inside rtol, at a third of DOP853's work."""
    sc, model, grid = load("one_dof_nonlinear_stiff")
    from smdcli.solvers.run import solve_scenario

    ours = solve_scenario(sc, model, grid)
    reference = solve(model, grid, "Radau", Tolerances(rtol=1e-12, atol=1e-16))
    dop853 = solve(model, grid, "DOP853", Tolerances(rtol=sc.solver.rtol, atol=sc.solver.atol))
    assert ours.stats.method == "taylor" and "not stiff" in ours.stats.reason
    assert relative_error(ours, reference) <= 1e-9
    assert relative_error(ours, reference) < relative_error(dop853, reference)
    assert ours.stats.nfev < dop853.stats.nfev / 2


def test_a_linear_scene_agrees_with_its_exact_modal_solution():
    """Three masses, a sine and a step: the exact recurrence is the independent reference (rounding-level)."""
    _, model, grid = load("three_dof_forced")
    exact = solve(model, grid, "exact", Tolerances())
    for rtol in (1e-7, 1e-10):
        ours = solve(model, grid, "taylor", Tolerances(rtol=rtol, atol=1e-14))
        assert relative_error(ours, exact) <= rtol


def chain_text(order: list[int]) -> str:
    """A chain of 12 unequal masses (so M^-1 K is not symmetric), a cubic spring at its root, a quadratic damper at
    its tip, a linear one at its root and one midway, two forces on its root and one midway, its masses declared in
    the given order (which numbers the DOFs)."""
    n = len(order)
    lines = ["[time]", "end = 3.0", "step = 0.01"]
    for i in order:
        lines += ["[[mass]]", f'name = "m{i}"', f"m = {1.0 + 0.1 * i}", f"x0 = {0.01 * math.sin(i)}"]
    lines += ["[[spring]]", 'connects = ["ground", "m0"]', "k = 100.0", 'law = "cubic"', "k3 = 1000.0"]
    lines += [f'[[spring]]\nconnects = ["m{i - 1}", "m{i}"]\nk = {100.0 + 5 * i}' for i in range(1, n)]
    lines += ["[[damper]]", 'connects = ["ground", "m0"]', "c = 0.5"]
    lines += ["[[damper]]", f'connects = ["m{n - 2}", "m{n - 1}"]', 'law = "quadratic"', "c = 2.0"]
    lines += ["[[damper]]", 'connects = ["m4", "m5"]', "c = 0.3"]
    lines += ["[[force]]", 'on = "m0"', 'type = "sine"', "amplitude = 10.0", "omega = 5.0"]
    lines += ["[[force]]", 'on = "m0"', 'type = "cosine"', "amplitude = 3.0", "omega = 7.0"]  # two on one DOF
    lines += ["[[force]]", 'on = "m7"', 'type = "sine"', "amplitude = 2.0", "omega = 3.0"]
    return "\n".join(lines) + "\n"


def test_rows_held_as_diagonals_and_as_sparse_rows_give_the_same_motion():
    """A chain numbered along itself has a band of half-width 1 (its stiffness's three diagonals summed in one pass);
    with its first two masses swapped, of half-width 2 (a pass per diagonal); numbered at random its band is wide,
    held as sparse rows. The three runs, put back in one order, are within rtol of a tight DOP853."""
    from smdcli.kernels.arrays import model_arrays
    from smdcli.kernels.diagonals import diagonals

    rtol = 1e-9
    names = [f"m{i}" for i in range(12)]
    runs = []
    for order in (list(range(12)), [1, 0, *range(2, 12)], [5, 11, 0, 7, 2, 9, 4, 1, 10, 3, 8, 6]):
        _, model, grid = model_of(chain_text(order))
        band, _, _ = diagonals(model_arrays(model))
        runs.append((band.shape[1], solve(model, grid, "taylor", Tolerances(rtol=rtol, atol=1e-14)), model))
    assert [width for width, _, _ in runs] == [3, 5, 0]
    model = runs[0][2]
    assert list(model.dofs) == names
    reference = solve(model, grid, "scipy:DOP853", TIGHT)
    peak = np.abs(reference.displacement).max()
    for _, result, numbered in runs:
        back = [numbered.dofs.index(name) for name in names]
        assert np.abs(result.displacement[:, back] - reference.displacement).max() <= rtol * peak


def test_the_accelerations_are_equilibriums_of_the_summed_states():
    """The acceleration rows come from the velocity's series; M a must balance the forces at the summed x and v."""
    _, model, grid = load("duffing_frequency_response")
    tol = Tolerances(rtol=1e-9, atol=1e-12)
    ours = solve(model, grid, "taylor", tol)
    balanced = model.acceleration(ours.displacement, ours.velocity, model.applied_force(grid))
    assert np.abs(ours.acceleration - balanced).max() <= 10 * tol.rtol * np.abs(balanced).max()


def test_a_support_motion_record_integrates_between_its_samples():
    """A ground acceleration table: linear between samples (its knots are restarts), -a_g on every DOF."""
    text = """
[time]
end = 2.0
step = 0.005
[[mass]]
name = "m"
m = 1.0
[[spring]]
connects = ["ground", "m"]
k = 400.0
law = "cubic"
k3 = 2.0e4
[[damper]]
connects = ["ground", "m"]
c = 0.4
[ground_motion]
quantity = "acceleration"
type = "table"
t = [0.0, 0.1, 0.25, 0.4, 0.7, 1.0, 1.3]
values = [0.0, 3.0, -4.0, 2.5, -1.0, 0.5, 0.0]
"""
    _, model, grid = model_of(text)
    ours = solve(model, grid, "taylor", Tolerances(rtol=1e-9, atol=1e-12))
    reference = solve(model, grid, "scipy:DOP853", TIGHT)
    assert ours.success and relative_error(ours, reference) <= 1e-9


def test_auto_takes_dop853_where_a_force_has_no_series_and_says_so():
    _, model, grid = model_of(FORCES)
    assert "chirp" in Taylor().refuse(model)
    r = solve(model, grid, "auto", Tolerances(rtol=1e-7, atol=1e-10))
    assert r.stats.method == "DOP853" and "no Taylor series for a chirp force" in r.stats.reason


def test_the_order_grows_with_the_tolerance_and_its_stability_limit_is_the_truncated_exponentials():
    """RK4's polynomial (order 4) is stable on the negative real axis to 2.7853; the order's limit is where
    |sum z^k / k!| first reaches 1, checked by evaluating the sum just inside and outside it."""
    assert abs(taylor_boundary(4) - 2.785293563405) < 1e-9
    for order in (8, 13, 17, 30):
        r = taylor_boundary(order)
        size = lambda z: abs(sum(z ** k / math.factorial(k) for k in range(order + 1)))  # noqa: E731
        assert size(-0.999 * r) <= 1 < size(-1.001 * r)
    assert [taylor_order(rtol) for rtol in (1e-4, 1e-6, 1e-8, 1e-10, 1e-14)] == sorted(
        taylor_order(rtol) for rtol in (1e-4, 1e-6, 1e-8, 1e-10, 1e-14))
    assert taylor_order(1e-8) > taylor_order(1e-4)


@pytest.mark.parametrize("case", ["at rest, pushed", "twins", "still"])
def test_a_quadratic_damper_whose_speed_starts_at_or_stays_at_zero(case):
    """d' = 0 at the start (its sign is then its acceleration's), d' = 0 throughout (two identical masses moving
    together: the damper never acts), and nothing moving at all: each as a tight DOP853 has it."""
    masses = ('[[mass]]\nname = "a"\nm = 1.0\nx0 = 0.1\n[[mass]]\nname = "b"\nm = 1.0\nx0 = 0.1\n'
              if case == "twins" else '[[mass]]\nname = "a"\nm = 1.0\n[[mass]]\nname = "b"\nm = 1.0\n')
    text = ("[time]\nend = 3.0\nstep = 0.01\n" + masses +
            '[[spring]]\nconnects = ["ground", "a"]\nk = 50.0\n[[spring]]\nconnects = ["ground", "b"]\nk = 50.0\n'
            '[[damper]]\nconnects = ["a", "b"]\nc = 30.0\nlaw = "quadratic"\n'
            '[[damper]]\nconnects = ["ground", "a"]\nc = 5.0\nlaw = "quadratic"\n'
            '[[damper]]\nconnects = ["ground", "b"]\nc = 5.0\nlaw = "quadratic"\n')
    if case == "at rest, pushed":
        text += '[[force]]\non = "a"\ntype = "step"\namplitude = 20.0\nt0 = 0.0\n'
    _, model, grid = model_of(text)
    ours = solve(model, grid, "taylor", Tolerances(rtol=1e-9, atol=1e-12))
    assert ours.success, ours.stats.message
    if case == "still":
        assert not np.any(ours.displacement) and not np.any(ours.velocity)
        return
    reference = solve(model, grid, "scipy:DOP853", TIGHT)
    assert relative_error(ours, reference) <= 1e-9
    if case == "twins":
        assert np.array_equal(ours.displacement[:, 0], ours.displacement[:, 1])


@pytest.mark.parametrize("rtol", [1e-6, 1e-9])
def test_every_row_of_x_v_and_a_is_within_rtol_whichever_series_sums_it(rtol):
    """A row in a step's first half is summed from that step's series; one in its second half from the next step's,
    nearer, where the motion is analytic across the step's end (not at a force's edge or a damper's reversal); each to
    the order it needs. x, v and a are each within rtol of a tight DOP853, against their own peaks, on the chain with a
    quadratic damper (reversals) and on every force with a series (edges; a is compared off them, where it has one
    value)."""
    from smdcli.solvers.base import cuts

    for text in (chain_text(list(range(12))), smooth_forces()):
        _, model, grid = model_of(text)
        ours = solve(model, grid, "taylor", Tolerances(rtol=rtol, atol=1e-14))
        reference = solve(model, grid, "scipy:DOP853", TIGHT)
        assert ours.success, ours.stats.message
        smooth = ~np.isin(grid, cuts(model, grid))
        for quantity in ("displacement", "velocity", "acceleration"):
            mine, theirs = getattr(ours, quantity)[smooth], getattr(reference, quantity)[smooth]
            assert np.abs(mine - theirs).max() <= rtol * np.abs(theirs).max(), quantity


def long_chain_text(case: str) -> str:
    """200 masses 3 s long: a wave travels about 30 of them; the rest stay at rest but for what is far under rtol."""
    n = 200
    driven = {"driven at its root": 0, "driven midway, its tip displaced": 100, "damped between masses": 0}[case]
    lines = ["[time]", "end = 3.0", "step = 0.01"]
    for i in range(n):
        x0 = 0.01 if case == "driven midway, its tip displaced" and i == n - 1 else 0.0
        lines += ["[[mass]]", f'name = "m{i}"', "m = 1.0", f"x0 = {x0}"]
    lines += ["[[spring]]", 'connects = ["ground", "m0"]', "k = 100.0"]
    lines += [f'[[spring]]\nconnects = ["m{i - 1}", "m{i}"]\nk = 100.0' for i in range(1, n)]
    lines += ["[[spring]]", f'connects = ["ground", "m{driven}"]', 'law = "cubic"', "k = 10.0", "k3 = 1000.0"]
    lines += ["[[damper]]", f'connects = ["ground", "m{driven}"]', "c = 0.5"]
    if case == "damped between masses":  # M^-1 C couples neighbours: the wave's terms spread a DOF an order
        lines += [f'[[damper]]\nconnects = ["m{i - 1}", "m{i}"]\nc = 0.2' for i in range(1, n)]
    lines += ["[[force]]", f'on = "m{driven}"', 'type = "sine"', "amplitude = 10.0", "omega = 5.0"]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("case", ["driven at its root", "driven midway, its tip displaced", "damped between masses"])
def test_a_long_chain_works_out_only_the_masses_its_motion_reaches_and_stays_within_rtol(case):
    """A step works out the series only at the DOFs the motion has reached (their x or v past a millionth of the
    step's tolerance) and those its terms can reach within the step; the rest stay exactly zero. x, v and a are within
    rtol of a tight DOP853 against their own peaks, the masses left at zero included, and most rows are those zeros."""
    rtol = 1e-8
    _, model, grid = model_of(long_chain_text(case))
    ours = solve(model, grid, "taylor", Tolerances(rtol=rtol, atol=1e-14))
    reference = solve(model, grid, "scipy:DOP853", TIGHT)
    assert ours.success, ours.stats.message
    for quantity in ("displacement", "velocity", "acceleration"):
        mine, theirs = getattr(ours, quantity), getattr(reference, quantity)
        assert np.abs(mine - theirs).max() <= rtol * np.abs(theirs).max(), quantity
    # the share of rows left at zero: from the first mass to the wave's front (midway: the front nearer the root, as
    # the span between the two loaded masses is worked out whole)
    assert (ours.displacement == 0.0).mean() > (0.25 if "midway" in case else 0.6)


@pytest.mark.parametrize("links_damped", [False, True])
def test_the_series_terms_are_zero_outside_the_span_a_step_works_out_and_reach_its_edge(links_damped):
    """A 60-mass chain moving only at masses 30-34: its series' terms of order k, worked out at every DOF, are zero
    outside terms_span, which the kernel works them out over, and reach its edge (v's terms spread a mass an order
    where dampers join the masses, else a mass each two orders): the span misses nothing and is no wider."""
    from smdcli.kernels.arrays import model_arrays
    from smdcli.kernels.taylor import coefficients, coupling_orders, diagonals, terms_span

    n, p, first, last = 60, 12, 30, 35
    lines = ["[time]", "end = 1.0", "step = 0.01"]
    lines += [f'[[mass]]\nname = "m{i}"\nm = 1.0\nx0 = {0.01 if first <= i < last else 0.0}' for i in range(n)]
    lines += ["[[spring]]", 'connects = ["ground", "m0"]', "k = 100.0"]
    lines += [f'[[spring]]\nconnects = ["m{i - 1}", "m{i}"]\nk = 100.0' for i in range(1, n)]
    if links_damped:
        lines += [f'[[damper]]\nconnects = ["m{i - 1}", "m{i}"]\nc = 0.5' for i in range(1, n)]
    _, model, _ = model_of("\n".join(lines) + "\n")
    m = model_arrays(model)
    band, spans, minv_diagonal = diagonals(m)
    orders = coupling_orders(band, spans)
    assert (band.shape[1], orders) == (3, 1 if links_damped else 2)
    Y = np.zeros((p + 1, 2 * n))
    Y[0, first:last] = 0.01
    Y[0, n + first:n + last] = np.linspace(1.0, 2.0, last - first)
    coefficients(m, band, spans, minv_diagonal, p, Y, np.zeros((p + 1, 0)), np.zeros((p + 1, 1)), np.zeros((p + 1, 1)),
                 np.zeros(1), 1.0, 0.0, np.zeros(n), 0, n, n, 1)  # every DOF of every order
    for k in range(p + 1):
        lowest, highest = terms_span(first, last, k, 1, orders, n)
        moving = np.flatnonzero((Y[k, :n] != 0) | (Y[k, n:] != 0))
        assert (moving.min(), moving.max() + 1) == (lowest, highest), k


@pytest.mark.parametrize("scene", ["a 200-mass chain, mostly at rest", "two masses, every force", "the book's damper"])
def test_the_extremes_found_as_the_rows_are_written_are_the_arrays_own(scene):
    """The kernel takes in each row's x and v as it writes them (and the zeros where the motion has not reached), so
    that the checks after a run need no pass over them: their least and largest values are the arrays' own, exactly
    (the same stored numbers compared). A run that fails finds none, and an array that is not the one written is
    passed over."""
    import dataclasses

    from smdcli.result import extremes

    if scene.startswith("the book"):
        _, model, grid = load("one_dof_nonlinear_stiff")
    else:
        _, model, grid = model_of(long_chain_text("driven at its root") if "chain" in scene else smooth_forces())
    ours = solve(model, grid, "taylor", Tolerances(rtol=1e-8, atol=1e-12))
    assert ours.success, ours.stats.message
    assert [array is getattr(ours, q) for (array, _), q in zip(ours.found_extremes, ("displacement", "velocity"))] \
        == [True, True]
    for quantity in ("displacement", "velocity"):
        assert ours.extremes_of(quantity) == extremes(getattr(ours, quantity)), quantity
    assert ours.extremes_of("displacement")[0] < 0.0 < ours.extremes_of("displacement")[1]
    moved = dataclasses.replace(ours, displacement=ours.displacement + 1.0)
    assert moved.extremes_of("displacement") == extremes(moved.displacement)
    failed = Taylor().solve(model, grid, Tolerances(rtol=1e-8, atol=1e-12, max_steps=3))
    assert not failed.success and failed.found_extremes == ()


def whole_and_chunked(model, grid, tol, monkeypatch, cores):
    """A Taylor run written whole (its rows zeroed by the kernel), and one zeroed ahead a chunk at a time
    (taylor_series.zeroed_ahead, as for an output larger than the caches) with this many cores."""
    from smdcli import interrupts
    from smdcli.solvers.integrators import taylor_series

    whole = Taylor().solve(model, grid, tol)
    monkeypatch.setattr(taylor_series, "ZEROED_IN_ONE_PASS", 0)
    monkeypatch.setattr(interrupts, "_usable_cores", cores)
    return whole, Taylor().solve(model, grid, tol)


@pytest.mark.parametrize("cores", [1, 2])
@pytest.mark.parametrize("case", ["driven midway, its tip displaced", "damped between masses"])
def test_a_run_zeroed_ahead_in_chunks_is_the_run_written_whole(case, cores, monkeypatch):
    """Zeroed ahead of the kernel in chunks (on a second core, or here first on one), the kernel stops before rows not
    yet zeroed and goes on from the same state, the stopped step worked out again: the same operations in the same
    order, so the same numbers in every row, the same extremes found and the same counts as the run written whole."""
    _, model, grid = model_of(long_chain_text(case))
    whole, chunked = whole_and_chunked(model, grid, Tolerances(rtol=1e-8, atol=1e-14), monkeypatch, cores)
    assert whole.success and chunked.success, chunked.stats.message
    for quantity in ("displacement", "velocity", "acceleration"):
        assert np.array_equal(getattr(whole, quantity), getattr(chunked, quantity)), quantity
        assert whole.extremes_of(quantity) == chunked.extremes_of(quantity)
    assert (whole.stats.nfev, whole.stats.steps_accepted) == (chunked.stats.nfev, chunked.stats.steps_accepted)


@pytest.mark.parametrize("cores", [1, 2])
def test_a_run_zeroed_ahead_that_fails_is_nan_from_where_it_stopped_to_the_end(cores, monkeypatch):
    """Its step budget spent partway, a run zeroed ahead in chunks stops where the run written whole stops: the rows
    before are its rows, every row after is NaN, the chunks zeroed after the stop included."""
    _, model, grid = model_of(long_chain_text("driven at its root"))
    whole, chunked = whole_and_chunked(model, grid, Tolerances(rtol=1e-8, atol=1e-14, max_steps=4), monkeypatch, cores)
    assert not whole.success and not chunked.success and whole.t_failed == chunked.t_failed < grid[-1]
    stopped = np.isnan(whole.displacement).all(axis=1)
    assert 1 < np.argmax(stopped) < len(grid) // 8 and stopped[np.argmax(stopped):].all()  # early: most chunks after
    for quantity in ("displacement", "velocity", "acceleration"):
        np.testing.assert_array_equal(getattr(whole, quantity), getattr(chunked, quantity), quantity)


def test_the_kernel_called_a_row_at_a_time_goes_on_where_it_stopped():
    """taylor.integrate with one more row ready each call (NEED_ROWS until the last) sums the same rows as one call
    with all of them ready: each stop keeps the whole state of the run (y, the series, the peaks, the span, the rows
    due), and the step it stopped before is worked out again from it."""
    from smdcli.kernels import taylor
    from smdcli.kernels.arrays import model_arrays
    from smdcli.solvers.base import cuts, divergence_bound

    _, model, grid = model_of(long_chain_text("damped between masses"))
    y0, p = np.concatenate([model.x0, model.v0]), 12
    outs, stops = [], 0
    for step in (len(grid), 1):
        out = np.zeros((3, len(grid), model.n))
        out[0, 0], out[1, 0] = model.x0, model.v0
        run = taylor.start_run(model_arrays(model), y0, p)
        counts, floats = np.zeros(5, dtype=np.int64), np.zeros(taylor.FLOATS)
        for ready in range(min(step + 1, len(grid)), len(grid) + step, step):
            status = taylor.integrate(model_arrays(model), grid, cuts(model, grid), 1e-12, 1e-18, 10**6,
                                      divergence_bound(model, grid), 0.0, out, True, min(ready, len(grid)), run,
                                      counts, floats)
            stops += status == taylor.NEED_ROWS
            if status != taylor.NEED_ROWS:
                break
        assert status == taylor.OK
        outs.append((out, counts.copy(), floats.copy()))
    (whole, whole_counts, whole_floats), (rowwise, counts, floats) = outs
    assert stops > len(grid) // 2  # most rows waited for
    assert np.array_equal(whole, rowwise) and np.array_equal(whole_counts, counts)
    assert np.array_equal(whole_floats, floats)
