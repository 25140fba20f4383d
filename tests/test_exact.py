"""The exact solver against closed forms, the book's formulas and independent tight integrations."""

import math

import numpy as np
import pytest
from conftest import SCENARIOS, force_block, model_of, one_dof
from scipy.integrate import solve_ivp

from smdcli import scenario
from smdcli.model import build, time_grid
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances


def load(name):
    sc = scenario.load(SCENARIOS / f"{name}.toml")
    return sc, build(sc), time_grid(sc.time)


def test_element_form_assembles_the_books_matrices():
    """C and K printed in the book's matrix approach (MASS3.m)."""
    _, model, _ = load("three_dof_forced")
    np.testing.assert_array_equal(model.M, np.diag([2.5, 2.0, 3.0]))
    np.testing.assert_array_equal(model.C, [[3, -0.5, 0], [-0.5, 4, -3.5], [0, -3.5, 3.5]])
    np.testing.assert_array_equal(model.K, [[30, -5, 0], [-5, 35, -30], [0, -30, 90]])


def test_element_and_matrix_forms_give_the_same_trajectories():
    _, element, grid = load("three_dof_free")
    _, matrix, grid2 = load("three_dof_matrix_free")
    a = solve(element, grid, "auto", Tolerances())
    b = solve(matrix, grid2, "auto", Tolerances())
    np.testing.assert_array_equal(grid, grid2)
    np.testing.assert_allclose(a.displacement, b.displacement, rtol=0, atol=1e-14)


def _book_three_dof(t, y):
    """three_MASS.m's third_DOF, transcribed: an independent right-hand side."""
    k1, k2, k3, k4, c1, c2, c3, m1, m2, m3 = 25, 5, 30, 30, 2.5, 0.5, 3.5, 2.5, 2, 3
    F1, F2, F3 = 20 * math.sin(120 * t), 0.0, 20.0
    return [y[1], (F1 - (k1 + k2) * y[0] + k2 * y[2] - (c1 + c2) * y[1] + c2 * y[3]) / m1,
            y[3], (F2 + k2 * y[0] - (k2 + k3) * y[2] + k3 * y[4] - (c2 + c3) * y[3] + c2 * y[1] + c3 * y[5]) / m2,
            y[5], (F3 + k3 * y[2] - (k3 + 2 * k4) * y[4] + c3 * y[3] - c3 * y[5]) / m3]


def test_three_dof_forced_matches_tight_integration_of_the_books_equations():
    sc, model, grid = load("three_dof_forced")
    grid = grid[grid <= 10.0]
    exact = solve(model, grid, "exact", Tolerances())
    ref = solve_ivp(_book_three_dof, (0, grid[-1]), np.zeros(6), method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-14)
    peak = np.abs(ref.y[0::2]).max()
    assert np.abs(exact.displacement - ref.y[0::2].T).max() / peak < 1e-10


def test_harmonic_steady_state_matches_equations_9_32_and_9_33():
    _, model, grid = load("one_dof_harmonic")
    r = solve(model, grid, "auto", Tolerances())
    assert r.stats.method == "exact"
    m, k, c, F0, w = 2.5, 25.0, 2.5, 10.0, 5.0
    wn = math.sqrt(k / m)
    zeta = c / (2 * math.sqrt(k * m))
    X = (F0 / m) / math.sqrt((wn**2 - w**2) ** 2 + (2 * zeta * wn * w) ** 2)  # (9-32)
    theta = math.atan2(2 * zeta * wn * w, wn**2 - w**2)  # (9-33), in [0, pi]
    tail = grid >= 30.0  # transient exp(-0.5 t) < 3e-7 of its start
    t = grid[tail]
    design = np.column_stack([np.cos(w * t), np.sin(w * t)])
    (a, b), *_ = np.linalg.lstsq(design, r.displacement[tail, 0], rcond=None)
    assert abs(math.hypot(a, b) - X) / X < 1e-5
    assert abs(math.atan2(b, a) - theta) < 1e-5
    assert abs(X - 0.25298) < 1e-5 and abs(theta - 2.8198) < 1e-4


def _tight_with_stops(model, grid, edges, forcing):
    """DOP853 at rtol 1e-12, restarted at every edge: an independent reference."""
    m, c, k = model.M[0, 0], model.C[0, 0], model.K[0, 0]
    y = [model.x0[0], model.v0[0]]
    out = np.empty(len(grid))
    cuts = [grid[0], *[e for e in edges if grid[0] < e < grid[-1]], grid[-1]]
    for ta, tb in zip(cuts[:-1], cuts[1:]):
        level = forcing(0.5 * (ta + tb))
        sel = (grid >= ta) & (grid <= tb)
        sol = solve_ivp(lambda t, s: [s[1], (level - c * s[1] - k * s[0]) / m], (ta, tb), y, method="DOP853",
                        rtol=1e-12, atol=1e-14, dense_output=True)
        out[sel] = sol.sol(grid[sel])[0]
        y = sol.y[:, -1]
    return out


def test_square_wave_matches_tight_run_stopping_at_every_edge():
    _, model, grid = load("one_dof_square_wave")
    r = solve(model, grid, "auto", Tolerances())
    assert r.stats.method == "exact"
    edges = np.arange(1, 14) * 1.0
    ref = _tight_with_stops(model, grid, edges, lambda t: 100.0 if math.floor(t) % 2 == 0 else -100.0)
    assert np.abs(r.displacement[:, 0] - ref).max() / np.abs(ref).max() < 1e-9


def test_edges_between_output_points_are_honoured():
    """A pulse from 0.0123 s to 0.0456 s on a 0.01 s grid: exact agrees with the tight stopped run."""
    text = one_dof(1.0, k=400.0, x0=0.0, end=2.0, step=0.01, extra=force_block("pulse", amplitude=50.0, t0=0.0123, duration=0.0333))
    _, model, grid = model_of(text)
    r = solve(model, grid, "exact", Tolerances())
    ref = _tight_with_stops(model, grid, [0.0123, 0.0456], lambda t: 50.0 if 0.0123 <= t < 0.0456 else 0.0)
    assert np.abs(r.displacement[:, 0] - ref).max() / np.abs(ref).max() < 1e-9


def test_fourier_square_matches_the_books_func_pulse_integrated_tightly():
    _, model, grid = load("one_dof_square_fourier")
    grid = grid[grid <= 4.0]
    r = solve(model, grid, "exact", Tolerances())
    n = np.arange(1, 114)
    coef = 200 / (n * np.pi) * (1 - np.cos(n * np.pi))

    def func_pulse(t):
        return coef @ np.sin(n * np.pi * t)

    np.testing.assert_allclose(r.force[:, 0], [func_pulse(t) for t in grid], rtol=0, atol=1e-9)
    ref = solve_ivp(lambda t, y: [y[1], (func_pulse(t) - 0.5 * y[1] - 1000 * y[0]) / 10], (0, grid[-1]), [0, 0],
                    method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-14)
    assert np.abs(r.displacement[:, 0] - ref.y[0]).max() / np.abs(ref.y[0]).max() < 1e-8


def test_table_force_is_exact_for_piecewise_linear_input():
    """A ramp F = 10 t on a table: the response to a ramp has a closed form."""
    text = one_dof(0.0, k=4.0, x0=0.0, end=3.0, step=0.01, extra=force_block("table", t=[0.0, 5.0], values=[0.0, 50.0]))
    _, model, grid = model_of(text)
    r = solve(model, grid, "auto", Tolerances())
    assert r.stats.method == "exact"
    # x'' + 4x = 10 t from rest: x = (10/4)(t - sin(2t)/2)
    np.testing.assert_allclose(r.displacement[:, 0], 2.5 * (grid - np.sin(2 * grid) / 2), rtol=0, atol=1e-13)


def test_undamped_resonance_is_exact():
    """x'' + x = cos t from rest: x = t sin(t) / 2 (the secular term)."""
    text = one_dof(0.0, k=1.0, x0=0.0, end=50.0, step=0.05, extra=force_block("cosine", amplitude=1.0, omega=1.0))
    _, model, grid = model_of(text)
    r = solve(model, grid, "exact", Tolerances())
    np.testing.assert_allclose(r.displacement[:, 0], grid * np.sin(grid) / 2, rtol=0, atol=1e-12)


def test_expression_force_first_order_hold_converges_at_second_order():
    """exact on an expression force holds it linearly on the grid: error falls 4x when the step halves."""
    def text(step):
        return one_dof(0.6, k=9.0, x0=0.0, end=10.0, step=step, extra=force_block("expression", expr="2*sin(1.3*t) + exp(-t)"))
    errors = []
    for step in (0.04, 0.02):
        _, model, grid = model_of(text(step))
        held = solve(model, grid, "exact", Tolerances())
        assert "first-order hold" in held.stats.message
        ref = solve_ivp(lambda t, y: [y[1], 2 * np.sin(1.3 * t) + np.exp(-t) - 0.6 * y[1] - 9 * y[0]], (0, 10),
                        [0, 0], method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-14)
        errors.append(np.abs(held.displacement[:, 0] - ref.y[0]).max())
        # the run says what it is: not "exact to rounding", its stated error above the one found
        assert "force[0] (expression) has no exact integral" in held.stats.reason
        assert "exact to rounding" not in held.stats.reason
        assert errors[-1] <= held.stats.stated_accuracy * np.abs(ref.y[0]).max()
    assert errors[0] < 1e-4
    assert 3.5 < errors[0] / errors[1] < 4.5
    _, model, grid = model_of(text(0.04))
    assert solve(model, grid, "auto", Tolerances()).stats.method == "DOP853"


def test_stiff_chain_agrees_with_a_40_digit_reference_to_1e_12():
    """The 1e6:1 two-mass chain, whose exact solution lost digits to scaling and squaring in double (5e-10 here,
    3.6e-9 on another CPU), against its eigen-solution in 40-digit arithmetic (mpmath), at every output time."""
    import mpmath as mp

    sc = scenario.load(SCENARIOS / "two_mass_stiff_chain.toml")
    model, grid = build(sc), time_grid(sc.time)
    A = model.state_matrix
    y0 = np.concatenate([model.x0, model.v0])
    with mp.workdps(40):
        values, vectors = mp.eig(mp.matrix(A.tolist()))
        weights = vectors**-1 * mp.matrix(y0.tolist())
        reference = np.array([[float(mp.re(sum(vectors[i, j] * weights[j] * mp.exp(values[j] * mp.mpf(float(t)))
                                                for j in range(4)))) for i in range(2)] for t in grid])
    result = solve(model, grid, "exact", Tolerances())
    peak = np.abs(reference).max()
    error = np.abs(result.displacement - reference).max() / peak
    assert error < 1e-12, error
    assert error <= result.stats.stated_accuracy
    assert "double-double" in result.stats.message


def test_accurate_exponential_is_correctly_rounded_on_random_matrices():
    """expm in double-double against mpmath's at 40 digits: within one rounding of the true entries."""
    import mpmath as mp

    from smdcli.solvers.exact.accurate_expm import expm_times

    rng = np.random.default_rng(7)
    for size, scale in ((3, 0.5), (6, 40.0), (10, 3000.0)):
        A = rng.standard_normal((size, size)) * scale - np.eye(size) * scale
        with mp.workdps(40):
            exact = np.array(mp.expm(mp.matrix(A.tolist()) * mp.mpf(0.01)).tolist(), dtype=float)
        assert np.abs(expm_times(A, 0.01) - exact).max() <= 2.3e-16 * np.abs(exact).max()


def _matrix_scene(M, C, K) -> str:
    rows = lambda A: "[" + ", ".join("[" + ", ".join(repr(float(a)) for a in row) + "]" for row in A) + "]"  # noqa: E731
    n = len(M)
    dofs = ", ".join(f'"x{i}"' for i in range(n))
    return (f"[time]\nend = 1.0\nstep = 0.1\n[system]\ndofs = [{dofs}]\nM = {rows(M)}\nC = {rows(C)}\nK = {rows(K)}\n"
            f"x0 = {[0.0] * n}\nv0 = {[1.0] + [0.0] * (n - 1)}\n")


def test_proportional_damping_modes_from_the_symmetric_solver_match_the_state_matrix_eigenvalues():
    """Rayleigh damping C = a M + b K (an underdamped, a critically damped region and overdamped high modes):
    the 1-DOF roots of each undamped mode against numpy's eigenvalues of the 2n x 2n state matrix."""
    from smdcli.model.system import _pair_modes

    n = 7
    K = 1000.0 * (2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1))
    M = np.diag(np.linspace(1.0, 2.5, n))
    C = 0.3 * M + 0.04 * K
    _, model, _ = model_of(_matrix_scene(M, C, K))
    assert model.proportional_damping
    modes = model.modes
    eig = np.linalg.eigvals(model.state_matrix)
    assert np.allclose(np.sort_complex(modes.eigenvalues), np.sort_complex(eig), rtol=1e-10, atol=1e-10)
    wn, zeta = _pair_modes(eig)
    order = np.argsort(wn)
    assert np.allclose(modes.natural_frequencies, wn[order], rtol=1e-10)
    assert np.allclose(modes.damping_ratios, zeta[order], rtol=1e-9)
    assert zeta.max() > 1 > zeta.min()  # both regimes present
    C[0, 1] = C[1, 0] = C[0, 1] + 0.5  # no longer proportional: the general eigenvalues
    _, other, _ = model_of(_matrix_scene(M, C, K))
    assert not other.proportional_damping


def _chain(n: int, ground_damper: float, chain_damper: float, force: str) -> str:
    lines = ["[time]", "end = 4.0", "step = 0.01"]
    for i in range(n):
        lines += ["[[mass]]", f'name = "m{i}"', f"m = {1.0 + 0.01 * i!r}", f"x0 = {0.001 * (i % 3)!r}"]
    lines += ["[[spring]]", 'connects = ["ground", "m0"]', "k = 1000.0",
              "[[damper]]", 'connects = ["ground", "m0"]', f"c = {ground_damper!r}"]
    for i in range(n - 1):
        lines += ["[[spring]]", f'connects = ["m{i}", "m{i + 1}"]', "k = 1000.0",
                  "[[damper]]", f'connects = ["m{i}", "m{i + 1}"]', f"c = {chain_damper!r}"]
    return "\n".join(lines) + "\n" + force


def test_modal_path_matches_the_dense_exponential_on_a_100_mass_chain(monkeypatch):
    """Classically damped (C = 0.002 K), a sine and a square force: modal coordinates against the dense 200-state
    exponential, to 1e-10 of the peak; a chain damped at one end only is not classical and stays dense."""
    import smdcli.solvers.exact.modal as modal

    forces = force_block("sine", on="m0", amplitude=10.0, omega=5.0) + \
        force_block("square", on="m50", amplitude=3.0, period=0.37, t0=0.05)
    _, model, grid = model_of(_chain(100, 2.0, 2.0, forces))
    assert modal.modal_applies(model)
    fast = solve(model, grid, "exact", Tolerances())
    assert "modal coordinates" in fast.stats.message
    monkeypatch.setattr(modal, "MODAL_DOFS", 10**9)
    dense = solve(model, grid, "exact", Tolerances())
    assert "modal" not in dense.stats.message
    for name in ("displacement", "velocity"):
        a, b = getattr(fast, name), getattr(dense, name)
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max(), name
    assert fast.stats.stated_accuracy <= 1e-9
    monkeypatch.undo()
    _, one_end, _ = model_of(_chain(100, 2.0, 0.0, forces))
    assert not one_end.proportional_damping and not modal.modal_applies(one_end)


def test_action_path_matches_the_dense_exponential_on_non_classical_chains(monkeypatch):
    """Damped at one end only (not classical): the exponential's sparse action against the dense 200-state
    exponential, to 1e-10 of the peak, with a sine, a square wave (force segments that fall between output
    points), a delayed step, a table and initial displacements; its stated accuracy covers the difference."""
    import smdcli.solvers.exact.linear as exact

    forces = force_block("sine", on="m0", amplitude=10.0, omega=5.0) + \
        force_block("square", on="m50", amplitude=3.0, period=0.37, t0=0.05) + \
        force_block("step", on="m99", amplitude=-2.0, t0=1.234) + \
        force_block("table", on="m20", t=[0.0, 1.0, 2.5, 4.0], values=[0.0, 5.0, -1.0, 0.0])
    _, model, grid = model_of(_chain(100, 2.0, 0.0, forces))
    assert not model.proportional_damping
    monkeypatch.setattr(exact, "dense_cost", lambda model, grid: math.inf)
    fast = solve(model, grid, "exact", Tolerances())
    assert "exponential's action" in fast.stats.message
    monkeypatch.setattr(exact, "ACTION_DOFS", 10**9)
    dense = solve(model, grid, "exact", Tolerances())
    assert "action" not in dense.stats.message
    for name in ("displacement", "velocity", "acceleration"):
        a, b = getattr(fast, name), getattr(dense, name)
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max(), name
    gap = np.abs(fast.displacement - dense.displacement).max() / np.abs(dense.displacement).max()
    assert gap <= fast.stats.stated_accuracy + dense.stats.stated_accuracy
    assert fast.stats.stated_accuracy <= 1e-9


def test_auto_takes_the_action_where_it_is_cheaper_and_says_so():
    """A 300-mass chain damped at one end: auto's exact path is the sparse action, named in its reason; a
    classically damped chain of the same size stays modal, and a 20-mass one dense."""
    forces = force_block("sine", on="m0", amplitude=10.0, omega=5.0)
    _, model, grid = model_of(_chain(300, 2.0, 0.0, forces))
    result = solve(model, grid, "auto", Tolerances())
    assert result.stats.method == "exact"
    assert "damping not proportional" in result.stats.reason and "sparse state matrix" in result.stats.reason
    assert "exponential's action" in result.stats.message
    _, classical, grid = model_of(_chain(300, 2.0, 2.0, forces))
    assert "modal coordinates" in solve(classical, grid, "auto", Tolerances()).stats.reason
    _, small, grid = model_of(_chain(20, 2.0, 0.0, forces))
    assert "matrix exponential" in solve(small, grid, "auto", Tolerances()).stats.reason


def test_large_non_classical_modes_come_from_modal_coordinates_and_equal_the_state_matrix_eigenvalues():
    """From 64 DOFs the damped eigenvalues are computed from [[0, I], [-Omega^2, -Phi^T C Phi]], a similarity
    transform of the state matrix: they equal the state matrix's own to 1e-12 of the largest, pair by pair."""
    from smdcli.model.system import MODAL_FORM_DOFS

    _, model, _ = model_of(_chain(MODAL_FORM_DOFS + 6, 2.0, 0.0, ""))
    assert not model.proportional_damping
    direct = np.linalg.eigvals(model.state_matrix)
    direct = direct[np.lexsort((direct.real, direct.imag))]
    eig = model.modes.eigenvalues
    assert len(eig) == len(direct)
    assert np.abs(eig - direct).max() <= 1e-12 * np.abs(direct).max()
    wn = np.sort(np.abs(direct[direct.imag > 0]))
    np.testing.assert_allclose(np.sort(model.modes.natural_frequencies), wn, rtol=1e-12)


def test_stacked_exponential_is_within_a_few_roundings_of_mpmaths():
    """expm_stack (Pade 13, each matrix scaled by its own power of two) against mpmath's at 40 digits, on a stack of
    the sizes and norms the modal path feeds it (a damped mode beside a force generator, ||A h||_1 up to 16)."""
    import mpmath as mp

    from smdcli.solvers.exact.accurate_expm import expm_stack

    rng = np.random.default_rng(11)
    stack = np.stack([rng.standard_normal((4, 4)) * scale for scale in (1e-3, 0.1, 1.0, 2.0, 4.0)])
    found = expm_stack(stack)
    for A, E in zip(stack, found):
        with mp.workdps(40):
            exact = np.array(mp.expm(mp.matrix(A.tolist())).tolist(), dtype=float)
        assert np.abs(E - exact).max() <= 1e-14 * np.abs(exact).max()


def test_a_chains_modes_from_the_tridiagonal_solver_equal_the_generalized_symmetric_ones():
    """A chain with a diagonal M: frequencies and mass-normalized shapes from MRRR on the tridiagonal M^-1/2 K M^-1/2,
    against scipy's generalized eigh(K, M) on the dense matrices; its accelerations from the CSR products against
    the dense M^-1 (F - C v - K x)."""
    from scipy.linalg import eigh

    _, model, grid = model_of(_chain(120, 2.0, 2.0, force_block("sine", on="m0", amplitude=10.0, omega=5.0)))
    squared, shapes = eigh(model.K, model.M)
    modes = model.modes
    assert np.abs(modes.natural_frequencies - np.sqrt(squared)).max() <= 1e-12 * np.sqrt(squared).max()
    signs = np.sign((modes.shapes * shapes).sum(axis=0))
    assert np.abs(modes.shapes - shapes * signs).max() <= 1e-9 * np.abs(shapes).max()
    run = solve(model, grid, "exact", Tolerances())
    dense = (run.force - run.velocity @ model.C.T - run.displacement @ model.K.T) @ np.linalg.inv(model.M).T
    assert np.abs(run.acceleration - dense).max() <= 1e-12 * np.abs(dense).max()


@pytest.mark.parametrize("stem", ["shock_half_sine", "three_dof_forced", "one_dof_square_fourier",
                                  "shear_frame_record"])
def test_a_grid_of_unequal_steps_gives_the_uniform_grids_values(stem):
    """The exact linear paths step a uniform grid; an internal caller's grid of other steps (a first step across a
    pulse's start, a point between samples, a finer stretch) is taken as its uniform runs. It once gave the first
    kind a wrong sign: +0.0031 m where the uniform grid gives -0.0032 m."""
    sc, model, grid = load(stem)
    uniform = solve(model, grid, "exact", Tolerances())
    i = len(grid) // 3
    h = grid[1] - grid[0]
    for times in (np.concatenate([[grid[0]], grid[i - 1:]]), np.union1d(grid, [grid[i] + 0.37 * h]),
                  np.concatenate([grid[:i], np.linspace(grid[i - 1], grid[i + 1], 21)[1:], grid[i + 2:]])):
        run = solve(model, times, "exact", Tolerances())
        shared = np.isin(times, grid)
        difference = np.abs(run.displacement[shared] - uniform.displacement[np.isin(grid, times)]).max()
        assert difference <= 1e-12 * np.abs(uniform.displacement).max()


@pytest.mark.parametrize("stem, params", [("three_dof_forced", ["spring[0].k", "damper[0].c"]),
                                          ("five_storey_building", ["spring[0].k"])])
def test_reads_of_the_same_entries_taken_together_give_each_reads_values(stem, params, monkeypatch):
    """propagate takes the readouts that reach the same state entries as one read (up to _MERGED_BYTES of output):
    the scene's and its sensitivities' histories are those of each readout taken alone, to rounding, and to the
    solve_ivp reference of the scene."""
    import smdcli
    from smdcli.solvers.exact import linear

    sc = scenario.load(SCENARIOS / f"{stem}.toml")
    together = smdcli.sensitivity(sc, params)
    monkeypatch.setattr(linear, "_MERGED_BYTES", 0)
    alone = smdcli.sensitivity(sc, params)
    for q in ("displacement", "velocity", "acceleration", "d_displacement", "d_velocity", "d_acceleration"):
        a, b = getattr(together, q), getattr(alone, q)
        assert np.abs(a - b).max() <= 1e-13 * np.abs(b).max(), q
    model = build(sc)
    reference = solve(model, together.time, "DOP853", Tolerances(rtol=1e-11, atol=1e-14))
    assert np.abs(together.displacement - reference.displacement).max() <= 1e-8 * np.abs(reference.displacement).max()


def test_the_dense_path_s_acceleration_is_the_equation_of_motion_with_each_force_at_its_time():
    """A sine and a cosine are read off their generators' states (g w, beside the structure's rows), a square wave
    and a delayed step are evaluated (a jump's sample its right limit): at every sample, on jumps too, the
    acceleration is M^-1 (B u(t) - C v - K x) with u evaluated, to 1e-13 of its peak, on a non-classical 6-mass
    chain."""
    from smdcli.solvers.exact import linear

    forces = force_block("sine", on="m0", amplitude=10.0, omega=5.0) + \
        force_block("cosine", on="m3", amplitude=4.0, omega=23.0, phase=0.3) + \
        force_block("square", on="m5", amplitude=3.0, period=0.37, t0=0.05) + \
        force_block("step", on="m2", amplitude=-2.0, t0=1.25)
    _, model, grid = model_of(_chain(6, 2.0, 0.0, forces))
    dense = model.dense()
    solved = linear.solve_dense(dense, grid)
    n = model.n
    u = model.forces(grid)
    expected = np.hstack([solved.x, solved.v]) @ dense.state_matrix[n:].T + u @ dense.input_matrix[n:].T
    assert np.abs(solved.acceleration - expected).max() <= 1e-13 * np.abs(expected).max()
    on_jumps = np.isin(np.round(grid, 9), np.round(0.05 + 0.185 * np.arange(30), 9))
    assert on_jumps.sum() >= 5  # samples on the square wave's jumps: right limits, as the signal gives them
