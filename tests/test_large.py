"""Large scenes: sparse assembly above SPARSE_DOFS masses, extrapolated sparse Newmark (compiled on the band, or on a
sparse LU), the result file of a sparse scene, against exact solutions, tight runs of other methods and closed
forms."""

import json
import math

import h5py
import numpy as np
import pytest
from conftest import model_of
from smdcli.model import build
from scipy.sparse import coo_matrix

import smdcli.model.sparse as sparse_module
import smdcli.solvers.auto as auto_module
from smdcli.errors import ScenarioError
from smdcli.io.hdf5 import read_matrix
from smdcli.kernels import banded
from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances
from smdcli.solvers.integrators.sparse_newmark import _March
from smdcli.solvers.registry import solver_class

SPARSE_DOFS = sparse_module.SPARSE_DOFS


def chain(n: int, *, cubic: bool = False, quadratic: bool = False, force: str = "sine", rayleigh: str = "",
          end: float = 4.0, step: float = 0.02, dampers: str = "every") -> str:
    """An n-mass chain fixed at one end: 1 kg and 100 N/m a link, 0.5 N s/m on every link (dampers "every") or on
    the first only ("first"); a force on the first mass; optionally its first spring cubic (k3 1000) and its last
    damper quadratic."""
    lines = ["[time]", f"end = {end}", f"step = {step}"]
    lines += [line for i in range(n) for line in ("[[mass]]", f'name = "m{i}"', "m = 1.0")]
    for i in range(n):
        left = "ground" if i == 0 else f"m{i - 1}"
        lines += ["[[spring]]", f'connects = ["{left}", "m{i}"]', "k = 100.0"]
        if i == 0 and cubic:
            lines += ['law = "cubic"', "k3 = 1000.0"]
        if dampers == "every" or i == 0:
            lines += ["[[damper]]", f'connects = ["{left}", "m{i}"]', "c = 0.5"]
        if i == n - 1 and quadratic:
            lines += ['law = "quadratic"']
    if force == "sine":
        lines += ["[[force]]", 'on = "m0"', 'type = "sine"', "amplitude = 10.0", "omega = 5.0"]
    elif force == "step":  # a jump between output points: the steps must land on it
        lines += ["[[force]]", 'on = "m0"', 'type = "step"', "amplitude = 10.0", "t0 = 0.513"]
    return "\n".join(lines + ([rayleigh] if rayleigh else [])) + "\n"


@pytest.fixture
def sparse_from_ten(monkeypatch):
    """Scenes of more than 10 masses assembled sparse, so that small ones test the path."""
    monkeypatch.setattr(sparse_module, "SPARSE_DOFS", 10)


def peak_error(x, reference) -> float:
    return float(np.abs(x - reference).max() / np.abs(reference).max())


def test_sparse_assembly_is_the_dense_one(sparse_from_ten):
    text = chain(12, cubic=True, quadratic=True, rayleigh="[damping]\nalpha = 0.1\nbeta = 0.002")
    _, sparse, _ = model_of(text)
    sparse_module.SPARSE_DOFS = SPARSE_DOFS
    _, dense, _ = model_of(text)
    assert sparse.is_sparse and not dense.is_sparse
    for name in ("M", "C", "K"):
        assert np.array_equal(getattr(sparse, name).toarray(), getattr(dense, name))
    assert np.array_equal(sparse.cubic.D, dense.cubic.D) and np.array_equal(sparse.quadratic.D, dense.quadratic.D)
    # Gershgorin's bound on the highest frequency: above it, and within its (loose) reach
    assert dense.omega_max <= sparse.omega_max <= 2 * dense.omega_max


def test_sparse_newmark_meets_its_tolerance(sparse_from_ten):
    _, model, grid = model_of(chain(40))
    reference = solve(model.dense(), grid, "exact", Tolerances())
    errors = []
    for rtol in (1e-6, 1e-8):
        run = solve(model, grid, "sparse_newmark", Tolerances(rtol=rtol, atol=1e-12))
        assert run.stats.method == "sparse_newmark" and run.success
        errors.append(peak_error(run.displacement, reference.displacement))
        # the stated error is the estimate of T32's: it bounds T33's, and meets rtol (10 rtol, as adaptive runs)
        assert errors[-1] <= run.stats.stated_accuracy <= 10 * rtol
    assert errors[1] < errors[0] / 100  # measured 1.2e-9 and 2.3e-12


@pytest.mark.parametrize("k, c, method", [(100.0, 0.5, "taylor"), (1e6, 0.5, "taylor"), (1e6, 5000.0, "sparse_newmark")])
def test_auto_gives_a_sparse_scene_to_the_taylor_series_where_stability_allows_it_long_steps(sparse_from_ten, k, c,
                                                                                           method):
    """Gershgorin's bound on |lambda|, c_max + omega_max = 4 c / m + 2 sqrt(k / m), over the series' stability
    boundary (7.70 at rtol 1e-6), in steps an output step of 0.02 s: 0.057 and 5.2 take the series, 57 (a stiffly
    damped chain) sparse Newmark. Each is within what it states of the exact solution; on the stiff chain whose high
    modes ring (k 1e6, c 0.5) Newmark's estimate misses rtol within 2 million steps, the series takes 3,500."""
    _, model, grid = model_of(chain(40).replace("k = 100.0", f"k = {k}").replace("c = 0.5", f"c = {c}"))
    reference = solve(model.dense(), grid, "exact", Tolerances())
    run = solve(model, grid, "auto", Tolerances(rtol=1e-6, atol=1e-12))
    assert run.success and run.stats.method == method and "40 DOFs, sparse" in run.stats.reason
    steps = (4 * c + 2 * math.sqrt(k)) * 0.02 / 7.70
    assert (steps <= auto_module.SPARSE_TAYLOR_STEPS) == (method == "taylor")
    assert peak_error(run.displacement, reference.displacement) <= run.stats.stated_accuracy
    assert f"no fewer than {steps:.2g} steps an output step" in run.stats.reason
    if method == "taylor":  # each step's terms held to rtol of x's peak and of v's: its statement holds for v too
        assert peak_error(run.velocity, reference.velocity) <= run.stats.stated_accuracy


@pytest.mark.parametrize("force, rayleigh", [("step", ""), ("sine", "[damping]\nalpha = 0.1\nbeta = 0.002")])
def test_the_taylor_series_on_a_sparse_scene_across_a_force_jump_and_with_rayleigh_damping(sparse_from_ten, force,
                                                                                           rayleigh):
    """The series on the sparse rows restarts at a step force's jump between output points, and takes [damping]'s
    Rayleigh C with the dampers': within what it states of the exact solution of the same scene made dense."""
    _, model, grid = model_of(chain(40, force=force, rayleigh=rayleigh))
    run = solve(model, grid, "auto", Tolerances(rtol=1e-8, atol=1e-12))
    assert model.is_sparse and run.stats.method == "taylor" and run.success
    reference = solve(model.dense(), grid, "exact", Tolerances())
    assert peak_error(run.displacement, reference.displacement) <= run.stats.stated_accuracy
    assert peak_error(run.velocity, reference.velocity) <= run.stats.stated_accuracy


def test_a_force_jump_between_output_points_is_a_step_end(sparse_from_ten):
    _, model, grid = model_of(chain(20, force="step"))
    run = solve(model, grid, "sparse_newmark", Tolerances(rtol=1e-8, atol=1e-12))
    reference = solve(model.dense(), grid, "exact", Tolerances())
    # across the jump the trapezoidal rule restarts from equilibrium: its error series holds on both sides
    assert peak_error(run.displacement, reference.displacement) < 1e-9
    assert peak_error(run.velocity, reference.velocity) < 1e-8


def test_nonlinear_chain_against_radau(sparse_from_ten):
    _, model, grid = model_of(chain(15, cubic=True, quadratic=True))
    reference = solve(model.dense(), grid, "Radau", Tolerances(1e-12, 1e-15))
    run = solve(model, grid, "auto", Tolerances(rtol=1e-8, atol=1e-12))
    assert run.stats.method == "taylor" and "nonlinear (spring[0], damper[14]), 15 DOFs, sparse" in run.stats.reason
    assert peak_error(run.displacement, reference.displacement) < 1e-8
    run = solve(model, grid, "sparse_newmark", Tolerances(rtol=1e-8, atol=1e-12))
    assert peak_error(run.displacement, reference.displacement) < 1e-8  # measured 3e-11


@pytest.mark.parametrize("linear", [False, True])  # a linear chain's steps: banded._chain_step's fused passes
@pytest.mark.parametrize("force", ["sine", "step"])
def test_band_kernel_and_sparse_lu_take_the_same_steps(sparse_from_ten, linear, force):
    _, model, grid = model_of(chain(25, cubic=not linear, quadratic=not linear, force=force))
    march = _March(model, grid, Tolerances())
    assert march.band is not None and march.band.stiffness.shape[0] == 2  # a chain: half-bandwidth 1
    x_band, v_band = march.run(2)
    x_lu, v_lu = march._run_sparse(2)
    assert peak_error(x_band, x_lu) < 1e-12 and peak_error(v_band, v_lu) < 1e-12


def test_a_doubled_pass_takes_the_last_pass_finer_runs_and_one_new_run(sparse_from_ten):
    _, model, grid = model_of(chain(25, cubic=True))
    march = _March(model, grid, Tolerances())
    march.extrapolated(1)
    first = march.steps
    x, v, estimate, extremes = march.extrapolated(2)
    assert march.steps - first == march.steps_per_pass(2) * 8 // 14  # the run at 8 divisions only: 8 of 2 + 4 + 8
    fresh = _March(model, grid, Tolerances())
    x_fresh, v_fresh, estimate_fresh, _ = fresh.extrapolated(2)
    assert peak_error(x, x_fresh) < 1e-14 and peak_error(v, v_fresh) < 1e-14  # the same runs, combined alike
    assert estimate == pytest.approx(estimate_fresh, rel=1e-6)
    assert extremes == ((x.min(), x.max()), (v.min(), v.max()))  # the table's blocks' extremes: the arrays'
    reference = solve(model.dense(), grid, "Radau", Tolerances(1e-12, 1e-15))
    assert peak_error(x, reference.displacement) < estimate[0] / np.abs(x).max()  # T32's estimate bounds T33's error


def test_a_pass_that_misses_its_tolerance_doubles_the_steps_with_one_new_run(sparse_from_ten):
    _, model, grid = model_of(chain(30))
    rtol = 5e-6  # the first pass (steps of 0.02, /2, /4) misses it by less than twice the steps make up for
    run = solve(model, grid, "sparse_newmark", Tolerances(rtol=rtol, atol=1e-14))
    reference = solve(model.dense(), grid, "exact", Tolerances())
    assert run.success and "steps of 0.01, /2 and /4 s extrapolated (Romberg) in 2 pass(es)" in run.notes[0]
    assert run.stats.steps_accepted == (len(grid) - 1) * (1 + 2 + 4 + 8)  # not (1 + 2 + 4) + (2 + 4 + 8)
    assert peak_error(run.displacement, reference.displacement) <= run.stats.stated_accuracy <= 10 * rtol


@pytest.mark.parametrize("width", [1, 3])
def test_band_cholesky_solve_and_product_against_dense_linear_algebra(width):
    rng = np.random.default_rng(width)
    n = 30
    dense = np.zeros((n, n))
    for d in range(1, width + 1):
        off = rng.normal(size=n - d)
        dense += np.diag(off, d) + np.diag(off, -d)
    dense += np.diag(np.abs(dense).sum(axis=1) + rng.uniform(0.5, 2.0, n))  # diagonally dominant: definite
    band = np.array([np.concatenate([np.diag(dense, -d), np.zeros(d)]) for d in range(width + 1)])
    x = rng.normal(size=n)
    out = np.zeros(n)
    banded.add_times(band, x, out)
    assert np.allclose(out, dense @ x, rtol=0, atol=1e-13 * np.abs(dense @ x).max())
    factor = band.copy()
    assert banded.cholesky(factor)
    b = dense @ x
    banded.solve(factor, b)
    assert np.abs(b - x).max() < 1e-13 * np.linalg.cond(dense) * np.abs(x).max()
    assert not banded.cholesky(band - np.array([[4 * np.abs(dense).max()] * n] + [[0.0] * n] * width))


def test_a_sparse_product_of_many_rows_keeps_their_layout(monkeypatch):
    monkeypatch.setattr(sparse_module, "VALUES_AT_ONCE", 8 * 40)  # blocks of 8 rows
    rng = np.random.default_rng(7)
    A = coo_matrix((rng.normal(size=300), (rng.integers(0, 40, 300), rng.integers(0, 30, 300))), shape=(40, 30))
    q = rng.normal(size=(3, 21, 40))  # 63 rows: seven blocks and a short last one
    product = sparse_module.rows_times(q, A.tocsr())
    assert product.shape == (3, 21, 30) and product.flags["C_CONTIGUOUS"]
    assert np.allclose(product, q @ A.toarray(), rtol=1e-13, atol=1e-13 * np.abs(q @ A.toarray()).max())


def test_other_methods_take_a_sparse_scene_dense(sparse_from_ten):
    _, model, grid = model_of(chain(12))
    run = solve(model, grid, "exact", Tolerances())
    reference = solve(model.dense(), grid, "exact", Tolerances())
    assert peak_error(run.displacement, reference.displacement) < 1e-13


def test_sparse_newmark_refuses_what_it_cannot_take():
    _, model, grid = model_of(chain(2) + '[[stop]]\nconnects = ["ground", "m0"]\nmax = 0.01\n')
    with pytest.raises(ScenarioError, match="'sparse_newmark' cannot take nonsmooth elements; stop\\[0\\]"):
        solve(model, grid, "sparse_newmark", Tolerances())
    shaken = chain(2, force="none") + '[ground_motion]\nquantity = "acceleration"\ntype = "sine"\namplitude = 1.0\n' \
        'omega = 3.0\n'
    _, model, grid = model_of(shaken)
    with pytest.raises(ScenarioError, match="'sparse_newmark' does not take a ground motion; try 'auto'"):
        solve(model, grid, "sparse_newmark", Tolerances())
    assert solver_class("sparse_newmark")().refuse(model_of(chain(2))[1]) is None


def test_only_a_scene_kept_dense_is_refused_for_its_dense_matrices_size(tmp_path, monkeypatch):
    """On a machine of 0.5 GB, 2,100 masses' dense matrices (12 n^2 doubles, 0.39 GB) do not fit in half of it: a chain
    kept sparse runs (its memory grows with its elements and output), the same chain with a stop is refused before
    it is assembled, saying why it is kept dense."""
    import smdcli
    import smdcli.resources as resources

    monkeypatch.setattr(resources, "physical_memory", lambda: 2 ** 29)
    scene = tmp_path / "long.toml"
    scene.write_text(chain(2100, end=0.2, step=0.01))
    assert smdcli.simulate(scene).success
    scene.write_text(chain(2100, end=0.2, step=0.01) + '[[stop]]\nconnects = ["ground", "m0"]\nmax = 1.0\n')
    with pytest.raises(ScenarioError, match=r"mass: 2100 DOFs need about 0.394 GB for their dense matrices \(kept "
                       r"dense because the scene has parts the sparse methods do not take \(stops, friction"):
        build(smdcli.load(scene))


def test_a_chain_above_sparse_dofs_from_the_command_line(cli, tmp_path, monkeypatch):
    """2,100 masses (sparse for real): the run, the file's chunked matrices, and its lowest modes against the fixed-
    free chain's closed form w_j = 2 sqrt(k/m) sin((2j - 1) pi / (2 (2n + 1)))."""
    import smdcli.io.hdf5 as hdf5

    monkeypatch.setattr(hdf5, "LARGE_VALUES", 100_000)  # the force's 212,100 values: its zero columns left unwritten
    n = 2100
    assert n > sparse_module.SPARSE_DOFS
    scene = tmp_path / "long.toml"
    scene.write_text(chain(n, end=1.0, step=0.01))
    ran = cli("simulate", scene, "-o", tmp_path / "out")
    assert ran.exit_code == 0, ran.output
    assert "taylor (linear, 2100 DOFs, sparse" in ran.stdout
    with h5py.File(tmp_path / "out" / "long.h5") as f:
        x = f["displacement"]
        assert x.shape == (101, n) and x.chunks is not None
        # a wave of at most 10 links a second (sqrt(k/m)) reaches a few dozen masses in 1 s; the rest stay at 0
        moved = np.flatnonzero(np.any(x[()] != 0, axis=0))
        assert np.array_equal(moved, np.arange(len(moved))) and len(moved) < 64
        assert x.id.get_storage_size() < x.nbytes / 20  # a chunk of 64 columns of 33 written
        force, t = f["force"], f["time"][()]
        assert force.shape == (101, n) and force.chunks is not None and force.attrs["units"] == "N"
        assert force.id.get_storage_size() < force.nbytes / 20  # one column's chunk of 33 written
        expected = np.zeros((101, n))
        expected[:, 0] = 10.0 * np.sin(5.0 * t)
        assert np.array_equal(force[()], expected)
        assert f["force"].dims[0][0] == f["time"] and f["force"].dims[1][0] == f["dof"]
        stored = f["model/K"]  # its nonzero entries only: what scipy's coo_matrix and MATLAB's sparse() read
        assert stored.attrs["format"] == "coordinate" and list(stored.attrs["shape"]) == [n, n]
        assert stored["value"].shape == (3 * n - 2,) and stored["value"].attrs["units"] == "N/m"
        K = coo_matrix((stored["value"][()], (stored["row"][()], stored["column"][()])), shape=(n, n)).toarray()
        assert np.array_equal(K[:3, :3], [[200.0, -100.0, 0.0], [-100.0, 200.0, -100.0], [0.0, -100.0, 200.0]])
        assert K[n - 1, n - 1] == 100.0 and K[0, n - 1] == 0.0
        assert np.array_equal(read_matrix(stored).toarray(), K)
        assert np.array_equal(read_matrix(f["model/M"]).diagonal(), np.ones(n))
        modes = f["model/modes"]
        lowest = modes.attrs["lowest"]
        assert lowest == 20 and modes["shapes"].shape == (n, 20)
        j = np.arange(1, lowest + 1)
        closed = 2 * math.sqrt(100.0) * np.sin((2 * j - 1) * math.pi / (2 * (2 * n + 1)))
        assert np.allclose(modes["natural_frequencies_rad_s"][()], closed, rtol=1e-8, atol=0)
        assert np.allclose(modes["damping_ratios"][()], 0.5 * closed / 200.0, rtol=1e-8)  # c_j = (c/k) w_j^2
        assert f.attrs["kind"] == "simulate" and f["solver"].attrs["method"] == "taylor"
    shown = cli("info", scene, "--json")
    assert shown.exit_code == 0, shown.output
    data = json.loads(shown.stdout)
    assert data["K"]["shape"] == [n, n] and len(data["K"]["values"]) == 3 * n - 2
    assert data["stiffness_ratio"] is None and len(data["modes"]) == 20 and data["auto"]["method"] == "taylor"
    refused = cli("info", scene, "--state-space", tmp_path / "ss.h5")
    assert refused.exit_code == 2 and "sparse scene" in refused.stderr and not (tmp_path / "ss.h5").exists()


def test_the_response_plots_of_a_wave_draw_masses_it_reached(sparse_from_ten):
    """A chain driven at one end for 1 s: the wave reaches the first few dozen of its 2,000 masses and leaves the rest
    at exactly 0 (the series works only where it has reached). The response and phase figures draw 10 DOFs evenly
    spaced among those that move, and say so, not 9 flat lines of masses it never reached."""
    from smdcli.plots.response import phase_figure, response_figure

    _, model, grid = model_of(chain(2000, end=1.0, step=0.001))
    run = solve(model, grid, "taylor", Tolerances(rtol=1e-8, atol=1e-12))
    moving = np.flatnonzero(np.any(run.displacement != 0, axis=0) | np.any(run.velocity != 0, axis=0))
    assert np.array_equal(moving, np.arange(len(moving))) and 10 < len(moving) < 200
    for figure in (response_figure(run, "chain"), phase_figure(run, "chain")):
        title = " ".join(text.get_text() for text in figure.texts + [ax.title for ax in figure.axes])
        assert f"10 of 2000 DOFs drawn, evenly spaced among the {len(moving)} that move" in title.replace("\n", " ")
        drawn = {int(name[1:]) for ax in figure.axes for name in ax.get_legend_handles_labels()[1]
                 if name.startswith("m")}
        assert len(drawn) == 10 and max(drawn) == len(moving) - 1
