"""The compiled kernels against independent code: scipy's integrators of the same tableaus, the numpy force
signals, the Model's own right-hand side and Jacobian, and the scipy path's results on the bundled scenes."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import bundled as load
from conftest import model_of

from smdcli.expression import FUNCTIONS, Expression
from smdcli.kernels.arrays import model_arrays
from smdcli.kernels.forces import force_value
from smdcli.kernels.rhs import jacobian, rhs, work_size
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

ROOT = Path(__file__).resolve().parents[1]

FORCES = """
[time]
end = 4.0
step = 0.01
[[mass]]
name = "a"
m = 2.0
[[mass]]
name = "b"
m = 1.0
[[spring]]
connects = ["ground", "a"]
k = 30.0
law = "cubic"
k3 = 400.0
[[spring]]
connects = ["a", "b"]
k = 10.0
[[damper]]
connects = ["a", "b"]
c = 0.8
law = "quadratic"
[[damper]]
connects = ["ground", "b"]
c = 0.2
[[force]]
on = "a"
type = "constant"
amplitude = 1.5
[[force]]
on = "a"
type = "step"
amplitude = 2.0
t0 = 0.5
[[force]]
on = "b"
type = "pulse"
amplitude = -1.0
t0 = 1.0
duration = 0.25
[[force]]
on = "a"
type = "pulse"
shape = "half_sine"
amplitude = 2.0
t0 = 0.3
duration = 0.4
[[force]]
on = "b"
type = "pulse"
shape = "haversine"
amplitude = -1.5
t0 = 1.7
duration = 0.6
[[force]]
on = "a"
type = "pulse"
shape = "triangle"
amplitude = 1.0
t0 = 2.2
duration = 0.5
[[force]]
on = "b"
type = "sine"
amplitude = 3.0
omega = 7.0
phase = 0.3
[[force]]
on = "a"
type = "cosine"
amplitude = 1.0
omega = 2.0
[[force]]
on = "b"
type = "square"
amplitude = 0.7
omega = 6.0
duty = 0.3
[[force]]
on = "a"
type = "fourier_square"
amplitude = 1.2
omega = 4.0
terms = 9
[[force]]
on = "b"
type = "chirp"
amplitude = 0.5
f0 = 0.2
f1 = 2.0
t1 = 4.0
[[force]]
on = "a"
type = "table"
t = [0.0, 1.0, 2.5, 4.0]
values = [0.0, 2.0, -1.0, 0.5]
[[force]]
on = "b"
type = "table"
t = [0.0, 1.5, 3.0]
values = [1.0, -2.0, 0.5]
interpolation = "previous"
[[force]]
on = "a"
type = "expression"
expr = "-sin(2*t)**2 + heaviside(t - 1) * exp(-t) / (1 + t) - abs(cos(3*t)) + sqrt(t) + tanh(t) * sign(t - 2)"
"""


@pytest.fixture(scope="module")
def forced():
    return model_of(FORCES)


def test_every_force_type_matches_the_numpy_signal_on_both_sides_of_its_edges(forced):
    _, model, grid = forced
    arrays = model_arrays(model)
    stack = np.zeros(work_size(arrays))
    edges = model.breakpoints(grid[0], grid[-1])
    times = np.concatenate([grid, edges, edges - 1e-9, edges + 1e-9, np.random.default_rng(1).uniform(0, 4, 200)])
    for j, signal in enumerate(model.signals):
        right = np.array([force_value(arrays, j, t, False, stack) for t in times])
        left = np.array([force_value(arrays, j, t, True, stack) for t in times])
        scale = max(1.0, np.abs(signal.value(times)).max())
        assert np.abs(right - signal.value(times)).max() <= 1e-13 * scale, model.force_types[j]
        assert np.abs(left - signal.value_left(times)).max() <= 1e-13 * scale, model.force_types[j]


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_every_expression_function_runs_compiled_as_numpy_evaluates_it(name):
    """The compiled interpreter reads smdcli.expression's opcodes: each function, and every operator around it."""
    from smdcli.kernels.forces import _expression

    text = f"-{name}(0.3 * t + 0.1) ** 2 / (1.5 + t) - 2 * t + 0.25"
    expression = Expression(text)
    codes, constants, depth = expression.program()
    times = np.linspace(0.05, 3.0, 41)
    stack = np.zeros(depth + 1)
    ours = np.array([_expression(np.array(codes, dtype=np.int64), np.array(constants), t, stack) for t in times])
    assert np.allclose(ours, expression(times), rtol=1e-14, atol=1e-14), name


def test_right_hand_side_and_jacobian_match_the_model(forced):
    _, model, _ = forced
    arrays = model_arrays(model)
    rng = np.random.default_rng(7)
    work = np.zeros(work_size(arrays))
    for t in (0.3, 1.1, 2.7):
        y = rng.normal(size=2 * model.n)
        dy = np.zeros_like(y)
        rhs(arrays, t, y, False, dy, work)
        expected = model.rhs(t, y, model.forces(t))
        assert np.allclose(dy, expected, rtol=1e-13, atol=1e-13 * np.abs(expected).max())
        J = np.zeros((2 * model.n, 2 * model.n))
        jacobian(arrays, y, J)
        assert np.allclose(J, model.jacobian(t, y), rtol=1e-13, atol=1e-12)


def element_chain(n: int) -> str:
    """n masses in a chain with a cubic spring and a quadratic damper midway and dampers at its ends."""
    lines = ["[time]", "end = 1.0", "step = 0.01"]
    lines += [f'[[mass]]\nname = "m{i}"\nm = {1.0 + 0.1 * i}' for i in range(n)]
    lines += ["[[spring]]", 'connects = ["ground", "m0"]', "k = 100.0"]
    lines += [f'[[spring]]\nconnects = ["m{i - 1}", "m{i}"]\nk = {100.0 + i}' for i in range(1, n)]
    half = n // 2
    lines += ["[[spring]]", f'connects = ["m{half - 1}", "m{half}"]', 'law = "cubic"', "k = 5.0", "k3 = 3000.0"]
    lines += ["[[damper]]", f'connects = ["ground", "m{half}"]', 'law = "quadratic"', "c = 2.0"]
    lines += ["[[damper]]", 'connects = ["ground", "m0"]', "c = 0.5"]
    lines += ["[[damper]]", f'connects = ["m{n - 2}", "m{n - 1}"]', "c = 0.3"]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("scene", ["two masses, every force", "a 40-mass chain"])
def test_the_stiffness_watchs_bound_takes_the_largest_row_and_bounds_every_eigenvalue(scene, forced):
    """spectral_bound looks only at the rows elements reach and the linear rows' largest sums (worked out once):
    the same bound as its formula over every row (c + sqrt(k), the largest row sums of |M^-1 K| and |M^-1 C| with
    each element's tangent added at its DOFs twice), and above |lambda| of the model's own Jacobian."""
    from smdcli.kernels.arrays import CUBIC_SPRING
    from smdcli.kernels.erk import linear_norms, spectral_bound

    model = forced[1] if scene.startswith("two") else model_of(element_chain(40))[1]
    arrays, n = model_arrays(model), model.n
    norms = linear_norms(arrays)
    rng = np.random.default_rng(3)
    for _ in range(5):
        y = rng.normal(size=2 * n)
        node = np.zeros(2 * n)
        for law, a, b, coefficient in zip(arrays.el_law, arrays.el_a, arrays.el_b, arrays.el_coef):
            offset = 0 if law == CUBIC_SPRING else n
            d = (y[offset + a] if a >= 0 else 0.0) - (y[offset + b] if b >= 0 else 0.0)
            slope = 3 * coefficient * d * d if law == CUBIC_SPRING else 2 * coefficient * abs(d)
            for dof in (a, b):
                if dof >= 0:
                    node[offset + dof] += 2 * slope
        minv = np.abs(model.Minv)
        k = (np.abs(model.Minv @ model.K).sum(axis=1) + minv @ node[:n]).max()
        c = (np.abs(model.Minv @ model.C).sum(axis=1) + minv @ node[n:]).max()
        bound = spectral_bound(arrays, y, norms, np.zeros(2 * n))
        assert bound == pytest.approx(c + np.sqrt(k), rel=1e-13)
        assert bound >= np.abs(np.linalg.eigvals(model.jacobian(0.0, y))).max()


@pytest.mark.parametrize("pair", ["RK45", "RK23", "DOP853"])
def test_compiled_pairs_take_scipys_steps_on_every_force_type(forced, pair):
    """Same tableau, same step control: the two agree far inside the tolerance, step counts within a few %."""
    _, model, grid = forced
    tol = Tolerances(rtol=1e-7, atol=1e-10)
    ours = solve(model, grid, pair, tol)
    theirs = solve(model, grid, f"scipy:{pair}", tol)
    assert ours.success and theirs.success
    peak = np.abs(theirs.displacement).max()
    assert np.abs(ours.displacement - theirs.displacement).max() <= 10 * tol.rtol * peak
    assert abs(ours.stats.steps_accepted - theirs.stats.steps_accepted) <= 0.05 * theirs.stats.steps_accepted + 2


@pytest.mark.parametrize("method", ["ode23s", "ode23t", "ode23tb", "Radau", "BDF"])
@pytest.mark.parametrize("scene", ["forced", "one_dof_nonlinear_stiff"])
def test_compiled_stiff_methods_take_the_python_formulas_steps(forced, scene, method):
    """The compiled Radau, BDF and ode23s/t/tb against scipy's Radau and BDF and smdcli.solvers.integrators.stiff23's classes
    on scipy's OdeSolver: same formulas and step control, so the same steps (within a few %: a step accepted at an
    error norm of 0.999 by one LU's rounding may be rejected by the other's) and agreement far inside the
    tolerance. The stiff scene's first 5 s (10,000 steps or so; its 20 s took scipy's Python formulas 40 s of CI)."""
    _, model, grid = forced if scene == "forced" else load(scene)
    grid = grid[grid <= 5.0]
    tol = Tolerances(rtol=1e-5, atol=1e-9)
    ours = solve(model, grid, method, tol)
    theirs = solve(model, grid, f"scipy:{method}", tol)
    assert ours.success and theirs.success
    peak = np.abs(theirs.displacement).max()
    assert np.abs(ours.displacement - theirs.displacement).max() <= tol.rtol * peak
    assert abs(ours.stats.steps_accepted - theirs.stats.steps_accepted) <= 0.05 * theirs.stats.steps_accepted + 2
    # After a marginal decision the step sequences part (BDF on the stiff scene: 4,227 and 4,268 steps, 9,364 and
    # 10,099 right-hand sides), so the work is compared more loosely than the steps.
    assert abs(ours.stats.nfev - theirs.stats.nfev) <= 0.10 * theirs.stats.nfev + 10


@pytest.mark.parametrize("method, dt", [("newmark", 2e-3), ("hht", 2e-3), ("generalized_alpha", 2e-3),
                                        ("central_difference", 2e-3), ("euler", 1e-5), ("rk4", 2e-2)])
def test_compiled_fixed_step_methods_hold_their_stated_accuracy_under_every_force_type(forced, method, dt):
    """Every force kind, restarts at each jump: within the accuracy each run states, against DOP853 at 1e-12."""
    _, model, grid = forced
    reference = solve(model, grid, "DOP853", Tolerances(rtol=1e-12, atol=1e-14))
    r = solve(model, grid, method, Tolerances(dt=dt))
    assert r.success, r.stats.message
    peak = np.abs(reference.displacement).max()
    error = np.abs(r.displacement - reference.displacement).max() / peak
    assert error <= r.stats.stated_accuracy, (error, r.stats.stated_accuracy)
    assert error < 1e-2  # and the statement says something


@pytest.mark.parametrize("name", ["one_dof_nonlinear_stiff", "duffing_frequency_response"])
@pytest.mark.parametrize("pair", ["RK45", "DOP853"])
def test_compiled_pairs_match_scipy_on_the_bundled_nonlinear_scenes(name, pair):
    _, model, grid = load(name)
    tol = Tolerances(rtol=1e-8, atol=1e-12)
    ours = solve(model, grid, pair, tol)
    theirs = solve(model, grid, f"scipy:{pair}", tol)
    peak = np.abs(theirs.displacement).max()
    # Each is within its stated accuracy of the truth, so of each other within the sum.
    bound = (ours.stats.stated_accuracy + theirs.stats.stated_accuracy) * peak
    assert np.abs(ours.displacement - theirs.displacement).max() <= bound


def test_default_settings_of_the_books_stiff_case_are_within_1e_8_of_a_tight_reference():
    sc, model, grid = load("one_dof_nonlinear_stiff")
    from smdcli.solvers.run import solve_scenario

    ours = solve_scenario(sc, model, grid)
    reference = solve(model, grid, "Radau", Tolerances(rtol=1e-12, atol=1e-16))
    peak = np.abs(reference.displacement).max()
    assert ours.stats.method == "taylor"
    assert np.abs(ours.displacement - reference.displacement).max() <= 1e-8 * peak


def test_the_stiffness_watch_reads_the_books_damper_as_not_stiff():
    """h |lambda| from the O(n) bound stays under half the boundaries of DOP853 and of auto's Taylor series along
    the run (exact eigenvalues: 1.2), but for one of DOP853's 846 steps at rtol 1e-6 (3.1 against 3.0)."""
    from smdcli.solvers.registry import solver_class

    DOP853 = solver_class("DOP853")
    sc, model, grid = load("one_dof_nonlinear_stiff")
    tol = Tolerances(rtol=1e-6, atol=1e-12)
    r = solve(model, grid, "auto", tol)
    assert r.stats.method == "taylor" and "not stiff" in r.stats.reason
    assert "on 0% of" in r.stats.reason
    explicit = DOP853(watch=True, land=True)
    explicit.solve(model, grid, tol)
    assert explicit.watch.share < 0.01 and explicit.watch.max_rho < 0.6 * DOP853.stability_boundary


def test_kernels_run_as_plain_python_without_the_compiler():
    """NUMBA_DISABLE_JIT=1: the same kernels interpreted, for coverage and debugging; same answer as scipy's. A test
    session starts so too: what its start asks of the cache (cached, warm) holds for plain functions, which have
    no compiled signatures (is_cached read them first, and pytest stopped with an internal error)."""
    code = ("import numpy as np\n"
            "from smdcli.solvers.integrators.compiled import KERNEL_FAMILIES, cached, warm\n"
            "assert all(cached(family) for family in KERNEL_FAMILIES)\n"
            "warm('erk')\n"
            "from conftest import bundled as load\n"
            "from smdcli.solvers import solve\n"
            "from smdcli.solvers.base import Tolerances\n"
            "_, m, g = load('duffing_frequency_response')\n"
            "g = g[:201]\n"
            "a = solve(m, g, 'DOP853', Tolerances(rtol=1e-7, atol=1e-10))\n"
            "b = solve(m, g, 'scipy:DOP853', Tolerances(rtol=1e-7, atol=1e-10))\n"
            "c = solve(m, g, 'taylor', Tolerances(rtol=1e-7, atol=1e-10))\n"
            "peak = np.abs(b.displacement).max()\n"
            "print(max(np.abs(a.displacement - b.displacement).max(), np.abs(c.displacement - b.displacement).max())"
            " / peak)\n")
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT / "tests", env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert float(done.stdout) < 1e-6


@pytest.mark.slow
def test_a_first_run_says_it_is_compiling(tmp_path):
    """With a kernel missing from numba's cache, smd says why it pauses (once), then runs; the next run is silent.
    The cache is this session's with ode113's one kernel, the right-hand side, taken out: that compiles in seconds,
    where an empty cache compiled every kernel it calls as well (36 s of CI)."""
    from numba.core.caching import UserProvidedCacheLocator

    from smdcli.kernels import compiler
    from smdcli.solvers.integrators.compiled import warm

    warm("rhs")  # in this session's cache, with every kernel it calls
    rhs = compiler._KERNELS / "rhs.py"
    cache = tmp_path / "cache"  # the folder a run under NUMBA_CACHE_DIR=cache finds the kernels in
    shutil.copytree(compiler._cache_folder(), cache / UserProvidedCacheLocator.get_suitable_cache_subpath(str(rhs)),
                    ignore=shutil.ignore_patterns("*.pyc", "rhs.state_rhs-*"))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    args = [sys.executable, "-m", "smdcli", "simulate", str(ROOT / "scenarios" / "one_dof_undamped.toml"),
            "--method", "ode113", "--no-plots", "-o", str(tmp_path)]
    first = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0 and "compiling kernels, once per install" in first.stderr
    second = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0 and "compiling" not in second.stderr


def test_no_kernel_is_compiled_twice_for_a_literal_argument():
    """A kernel calling another with a literal (a method code, row 1, the no-guard -1, False) makes numba compile a
    copy of the callee for that constant beside the one for int64 or bool: 27 kernels had such copies, and without
    them the compile chains took 155 s and 161 s where they took 305 s and 301 s. With every family compiled, numba's cache index (the callees' too, which a kernel loaded
    from the cache does not show) holds no two overloads of one kernel, for one CPU, that differ only in literals."""
    import pickle

    from numba.core import types

    from smdcli.kernels import compiler
    from smdcli.solvers.integrators.compiled import KERNEL_FAMILIES, warm

    warm(*KERNEL_FAMILIES)
    indexes = sorted(compiler._cache_folder().glob("*.nbi"))
    assert len(indexes) > 50
    twice = []
    for index in indexes:
        with open(index, "rb") as f:
            pickle.load(f)  # numba's index format version
            _, overloads = pickle.loads(f.read())
        plain = [(tuple(map(types.unliteral, key[0])), key[1]) for key in overloads]  # (signature, CPU)
        if len(set(plain)) < len(plain):
            twice.append((index.name, [str(key[0]) for key in overloads]))
    assert not twice, twice


def test_a_changed_kernel_source_clears_the_cached_kernels(tmp_path, monkeypatch):
    """numba keys a cached kernel on its own file only; an integrator inlines rhs.py, so a change there must clear
    every cached kernel (stale machine code once ran the old force code under a new one), and nothing else."""
    from smdcli.kernels import compiler

    sources = []
    for name in ("rhs.py", "fixed.py"):
        (tmp_path / name).write_text(f"# {name}\n")
        sources.append(tmp_path / name)
    cache = tmp_path / "cache"
    cache.mkdir()
    monkeypatch.setattr(compiler, "_SOURCES", tuple(sources))
    monkeypatch.setattr(compiler, "_cache_folder", lambda: cache)
    ours = [cache / "fixed.march-160.py311.nbi", cache / "fixed.march-160.py311.1.nbc", cache / "rhs.rhs-169.py311.nbi"]
    theirs = cache / "other.kernel-3.py311.nbi"
    for path in (*ours, theirs):
        path.write_bytes(b"x")
    assert compiler.clear_stale_cache()  # no stamp yet: whatever is there was compiled from unknown sources
    assert not any(path.exists() for path in ours) and theirs.exists()
    ours[0].write_bytes(b"x")
    assert not compiler.clear_stale_cache() and ours[0].exists()  # same sources: the cache is kept
    sources[0].write_text("# rhs.py, changed\n")
    assert compiler.clear_stale_cache() and not ours[0].exists()


def test_steps_landed_on_a_quadratic_dampers_reversals_cost_fewer_tries_at_no_loss_of_accuracy():
    """The book's c |v| v damper reverses 200 times in 20 s; a step that ends at each reversal (where c |v| v has no
    second derivative) replaces the rejected tries of a step across it, and is as accurate against a tight Radau."""
    from smdcli.solvers.registry import solver_class

    DOP853 = solver_class("DOP853")
    _, model, grid = load("one_dof_nonlinear_stiff")
    tol = Tolerances(rtol=1e-8, atol=1e-13)
    across, landed = DOP853().solve(model, grid, tol), DOP853(land=True).solve(model, grid, tol)
    reference = solve(model, grid, "Radau", Tolerances(rtol=1e-12, atol=1e-16))
    peak = np.abs(reference.displacement).max()
    errors = [np.abs(r.displacement - reference.displacement).max() / peak for r in (across, landed)]
    reversals = np.count_nonzero(np.diff(np.sign(reference.velocity[:, 0])))
    assert reversals >= 190
    # every reversal costs the landed run one cut-short try, the other three rejected tries or more
    assert landed.stats.steps_rejected <= reversals + 0.5 * (across.stats.steps_rejected - reversals)
    assert landed.stats.nfev < 0.85 * across.stats.nfev
    assert errors[1] <= 1e-8 and errors[1] <= 1.5 * errors[0], errors
