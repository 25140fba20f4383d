"""[system]'s M, C, K read from Matrix Market, scipy .npz and MATLAB .mat files: the same scene as written inline,
a large chain kept sparse against its element form and its closed-form modes, and every way such a file can be
wrong refused in one line."""

from __future__ import annotations

import hashlib
import math
import re

import h5py
import numpy as np
import pytest
import scipy.io
import scipy.linalg
import scipy.sparse
from conftest import SCENARIOS, chain_files, chain_matrices

import smdcli
from smdcli.errors import ScenarioError
from smdcli.io.hdf5 import read_matrix
from smdcli.model import build
from smdcli.model import sparse as sparse_module
from smdcli.solvers.peaks import result_peaks

BOOK = SCENARIOS / "three_dof_matrix_forced.toml"
FORMATS = (".mtx", ".npz", ".mat")


def _book_matrices() -> dict[str, np.ndarray]:
    """The book's printed M, C, K (Equations 9-42 to 9-47) as the inline scenario gives them."""
    sc = smdcli.load(BOOK)
    return {key: np.array(getattr(sc.system, key)) for key in "MCK"}


def _write(path, matrix, key: str, dense: bool = False) -> None:
    """One matrix in the format of path's suffix, sparse unless dense."""
    stored = matrix if dense else scipy.sparse.csr_matrix(matrix)
    if path.suffix == ".mtx":
        scipy.io.mmwrite(path, stored)
    elif path.suffix == ".npz":
        if dense:
            np.savez(path, **{key: matrix})
        else:
            scipy.sparse.save_npz(path, stored)
    else:
        scipy.io.savemat(path, {key: stored})


def _book_from_files(folder, suffix: str, dense: bool = False, dofs: bool = False):
    """The book's matrix scenario with its matrices moved into files of one format."""
    text = BOOK.read_text()
    for key, matrix in _book_matrices().items():
        _write(folder / f"book_{key}{suffix}", matrix, key, dense)
        text = re.sub(rf"^{key} = \[\[.*$", f'{key} = "book_{key}{suffix}"', text, flags=re.M)
    if not dofs:
        text = text.replace('dofs = ["x1", "x2", "x3"]\n', "")
    scene = folder / "book.toml"
    scene.write_text(text)
    return scene


@pytest.mark.parametrize("suffix", FORMATS)
@pytest.mark.parametrize("dense", [False, True], ids=["sparse", "dense"])
def test_the_books_matrices_from_files_solve_as_written_inline(tmp_path, suffix, dense):
    """Read from each format (sparse or dense arrays in it: Matrix Market's coordinate or array form), the book's three-DOF system is the same model and the
    same run as the inline one: the same numbers in M, C, K, and displacements to rounding of the exact solution."""
    scene = _book_from_files(tmp_path, suffix, dense)
    filed, inline = smdcli.load(scene), smdcli.load(BOOK)
    assert filed.dof_names == ("x1", "x2", "x3")  # dofs defaulted: x1..xn, as the force on x2 names
    a, b = build(filed), build(inline)
    for key in "MCK":
        assert np.array_equal(getattr(a, key), getattr(b, key)), key
    ran, reference = smdcli.simulate(filed), smdcli.simulate(inline)
    assert ran.stats.method == reference.stats.method == "exact"
    peak = np.abs(reference.displacement).max()
    assert np.abs(ran.displacement - reference.displacement).max() <= 1e-12 * peak


def test_named_dofs_and_inline_matrices_join_the_files(tmp_path):
    """dofs name the rows when given; a matrix written inline beside files (a sweep's zeta writes C so) joins them."""
    scene = _book_from_files(tmp_path, ".mtx", dofs=True)
    text = scene.read_text().replace('dofs = ["x1", "x2", "x3"]', 'dofs = ["a", "b", "c"]').replace('on = "x2"',
                                                                                                    'on = "b"')
    text = text.replace('C = "book_C.mtx"', "C = [[3.0, -0.5, 0.0], [-0.5, 4.0, -3.5], [0.0, -3.5, 3.5]]")
    scene.write_text(text)
    model = build(smdcli.load(scene))
    assert model.dofs == ("a", "b", "c")
    assert np.array_equal(model.C, _book_matrices()["C"])


def test_a_consistent_mass_matrix_is_solved_dense(tmp_path):
    """A non-diagonal M (a finite-element consistent mass) from a file: the exact solution of M x'' + K x = 0 from
    x0 along a mode is that mode's cosine, x(t) = x0 cos(w t), w^2 the generalized eigenvalue."""
    M = np.array([[2.0, 0.5, 0.0], [0.5, 2.0, 0.5], [0.0, 0.5, 1.0]])
    K = np.array([[200.0, -100.0, 0.0], [-100.0, 200.0, -100.0], [0.0, -100.0, 100.0]])
    squared, shapes = scipy.linalg.eigh(K, M)
    w, shape = math.sqrt(squared[1]), shapes[:, 1] / np.abs(shapes[:, 1]).max()
    for key, matrix in (("M", M), ("K", K)):
        scipy.io.mmwrite(tmp_path / f"{key}.mtx", scipy.sparse.csr_matrix(matrix))
    scene = tmp_path / "consistent.toml"
    scene.write_text('[time]\nend = 2.0\nstep = 0.01\n[system]\nM = "M.mtx"\nK = "K.mtx"\n'
                     f"x0 = [{', '.join(repr(float(v)) for v in shape)}]\n")
    ran = smdcli.simulate(scene)
    closed = np.cos(w * ran.time)[:, None] * shape[None, :]
    assert np.abs(ran.displacement - closed).max() <= 1e-11


@pytest.mark.parametrize("suffix", FORMATS)
def test_a_chain_from_files_above_sparse_dofs_is_its_element_form(tmp_path, suffix):
    """2,010 masses from files stay sparse (CSR in the model, nonzero entries in the file) and run as the same chain
    in [[mass]] tables does, within the error each run states; its lowest modes are the fixed-free chain's closed
    form w_j = 2 sqrt(k/m) sin((2j - 1) pi / (2 (2n + 1)))."""
    from test_large import chain

    n = sparse_module.SPARSE_DOFS + 10
    scene = chain_files(tmp_path, n, suffix, end=1.0, step=0.01)
    model = build(smdcli.load(scene))
    assert model.is_sparse and model.M.nnz == n and model.K.nnz == 3 * n - 2
    lowest = model.modes.natural_frequencies
    j = np.arange(1, len(lowest) + 1)
    closed = 2 * math.sqrt(100.0) * np.sin((2 * j - 1) * math.pi / (2 * (2 * n + 1)))
    assert np.allclose(lowest, closed, rtol=1e-8, atol=0)
    ran = smdcli.simulate(scene)
    element_form = tmp_path / "elements.toml"
    element_form.write_text(chain(n, end=1.0, step=0.01).replace('on = "m0"', 'on = "m0"'))
    reference = smdcli.simulate(element_form)
    assert ran.stats.method == reference.stats.method == "taylor"
    peak = np.abs(reference.displacement).max()
    allowed = 10 * (ran.stats.stated_accuracy + reference.stats.stated_accuracy) * peak
    assert np.abs(ran.displacement - reference.displacement).max() <= allowed
    written = smdcli.write(ran, tmp_path / "chain.h5")
    with h5py.File(written) as f:
        K = f["model/K"]
        assert K.attrs["format"] == "coordinate" and K["value"].shape == (3 * n - 2,)
        assert (read_matrix(K) != chain_matrices(n)[2]).nnz == 0
        origin = f["provenance/matrix_files"].attrs
        assert origin["K_file"].endswith(f"chain_K{suffix}") and len(origin["K_sha256"]) == 64
        assert origin["K_sha256"] == hashlib.sha256((tmp_path / f"chain_K{suffix}").read_bytes()).hexdigest()


def test_a_sweep_of_a_scene_from_files_is_each_member_simulated(tmp_path, cli):
    """A force amplitude swept over the book's system from files: each member's peak is simulate's."""
    scene = _book_from_files(tmp_path, ".npz")
    swept = cli("sweep", scene, "--param", "force[0].amplitude", "--values", "10,20", "-o", tmp_path / "out",
                "--no-plots")
    assert swept.exit_code == 0, swept.output
    with h5py.File(tmp_path / "out" / "book_sweep.h5") as f:
        peaks = f["metrics/peak_displacement"][()]
    one = result_peaks(smdcli.simulate(scene))  # located between samples, as the sweep's metric is
    np.testing.assert_allclose(peaks[1], one, rtol=1e-9)
    np.testing.assert_allclose(peaks[0], one / 2, rtol=1e-9)


@pytest.mark.parametrize("command", ["sweep", "sensitivity"])
def test_an_entry_of_a_matrix_from_a_file_is_refused_as_such(tmp_path, cli, command):
    """system.K[0][0] of a K read from a file: one line naming the file and the way out (the matrix inline), exit 2,
    nothing written; not "system.K has no entry [0]", which says the matrix is not there."""
    scene = _book_from_files(tmp_path, ".mtx")
    values = ["--values", "90,110"] if command == "sweep" else []
    ran = cli(command, scene, "--param", "system.K[0][0]", *values, "-o", tmp_path / "out")
    assert ran.exit_code == 2
    assert ran.output.strip().splitlines() == [
        "smd: --param system.K[0][0]: system.K is read from the file 'book_K.mtx', whose entries cannot be varied; "
        "write system.K inline to vary an entry"]
    assert not (tmp_path / "out").exists()


def _bad(tmp_path, system: str, files: dict) -> tuple:
    """A scene whose [system] is `system` with files written beside it: (scenario path, output folder)."""
    for name, write in files.items():
        write(tmp_path / name)
    scene = tmp_path / "bad.toml"
    scene.write_text(f"[time]\nend = 1.0\nstep = 0.1\n[system]\n{system}\n")
    return scene


def _mtx(matrix):
    return lambda path: scipy.io.mmwrite(path, scipy.sparse.csr_matrix(np.asarray(matrix, dtype=float)))


SPRING = [[100.0, -50.0], [-50.0, 50.0]]
MASS = [[1.0, 0.0], [0.0, 1.0]]
BAD = {
    "no such file": ('M = "M.mtx"\nK = "missing.mtx"', {"M.mtx": _mtx(MASS)}, "system.K: ", "missing.mtx: no such file"),
    "unknown format": ('M = "M.csv"\nK = "K.mtx"', {"M.csv": lambda p: p.write_text("1,0\n0,1\n"), "K.mtx": _mtx(SPRING)},
                       "system.M: ", "expected a Matrix Market (.mtx), scipy (.npz) or MATLAB (.mat) file, found 'M.csv'"),
    "not Matrix Market": ('M = "M.mtx"\nK = "K.mtx"', {"M.mtx": lambda p: p.write_text("1 0\n0 1\n"),
                                                      "K.mtx": _mtx(SPRING)}, "system.M: ", "cannot be read as a .mtx"),
    "not square": ('M = "M.npz"\nK = "K.mtx"', {"M.npz": lambda p: np.savez(p, M=np.ones((2, 3))),
                                                "K.mtx": _mtx(SPRING)}, "system.M: ", "expected a square matrix, found 2 x 3"),
    "sizes differ": ('M = "M.mtx"\nK = "K.mtx"', {"M.mtx": _mtx(MASS), "K.mtx": _mtx(np.eye(3))},
                     "system.K: ", "expected a 2 x 2 matrix (as M is), found 3 x 3"),
    "dofs disagree": ('dofs = ["a", "b", "c"]\nM = "M.mtx"\nK = "K.mtx"', {"M.mtx": _mtx(MASS), "K.mtx": _mtx(SPRING)},
                      "system.M: ", "expected a 3 x 3 matrix (one row per name in dofs), found 2 x 2"),
    "asymmetric": ('M = "M.mtx"\nK = "K.mtx"', {"M.mtx": _mtx(MASS), "K.mtx": _mtx([[100.0, -50.0], [-40.0, 50.0]])},
                   "system.K: ", "expected a symmetric matrix, found K[0][1] = -50 but K[1][0] = -40"),
    "not finite": ('M = "M.npz"\nK = "K.mtx"', {"M.npz": lambda p: np.savez(p, M=np.array([[1.0, 0], [0, np.nan]])),
                                                "K.mtx": _mtx(SPRING)}, "system.M: ", "expected finite numbers, found nan in row 1"),
    "massless DOF": ('M = "M.mtx"\nK = "K.mtx"', {"M.mtx": _mtx([[1.0, 0.0], [0.0, 0.0]]), "K.mtx": _mtx(SPRING)},
                     "system.M: ", "expected a symmetric positive definite matrix; M.mtx has M[1][1] = 0"),
    "indefinite K": ('M = "M.mtx"\nK = "K.mtx"', {"M.mtx": _mtx(MASS), "K.mtx": _mtx([[1.0, 2.0], [2.0, 1.0]])},
                     "system.K: ", "expected a symmetric positive semi-definite matrix; K.mtx is not"),
    "several arrays": ('M = "M.mtx"\nK = "both.npz"', {"M.mtx": _mtx(MASS), "both.npz": lambda p: np.savez(
        p, A=np.eye(2), B=np.eye(2))}, "system.K: ", "holds A, B; expected one matrix or one named K"),
    "complex": ('M = "M.mat"\nK = "K.mtx"', {"M.mat": lambda p: scipy.io.savemat(p, {"M": np.eye(2) * (1 + 1j)}),
                                             "K.mtx": _mtx(SPRING)}, "system.M: ", "expected a real matrix"),
    "MATLAB v7.3": ('M = "M.mat"\nK = "K.mtx"', {"M.mat": lambda p: h5py.File(p, "w").close(), "K.mtx": _mtx(SPRING)},
                    "system.M: ", "M.mat: "),
    "no K": ('M = "M.mtx"', {"M.mtx": _mtx(MASS)}, "system.K: ", "required field is missing"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_matrix_file_is_one_line_exit_2_nothing_written(tmp_path, cli, case):
    """Each way a matrix file can be wrong: exit 2, one line naming the scenario, the field and the file."""
    system, files, field, message = BAD[case]
    scene = _bad(tmp_path, system, files)
    out = tmp_path / "out"
    ran = cli("simulate", scene, "-o", out)
    assert ran.exit_code == 2, ran.output
    lines = ran.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in ran.output, ran.stderr
    assert lines[0].startswith(f"smd: {scene}: {field}"), lines[0]
    assert message in lines[0], lines[0]
    assert not out.exists() or not any(out.iterdir())


def _tridiagonal(n: int, diagonal, off: float):
    """A symmetric tridiagonal matrix (CSR) of this diagonal (array or number) and off-diagonal."""
    return scipy.sparse.diags([np.broadcast_to(diagonal, (n,)), np.full(n - 1, off), np.full(n - 1, off)],
                              [0, 1, -1], format="csr")


def test_a_narrow_matrix_of_any_size_is_proven_definite_by_its_banded_factor(tmp_path):
    """Beyond the dense check's 2,000 DOFs a narrow matrix is still factored (banded): a 3,000-DOF tridiagonal K whose
    diagonal is positive but which is indefinite (1 on the diagonal, -1 beside it: eigenvalues down to 1 - 2 cos(pi /
    3001) < 0) is refused, a free-free chain's singular semi-definite K is taken, and the banded verdict agrees with
    scipy's dense eigenvalues on a smaller such pair."""
    from smdcli.scenario.matrix_files import _factors

    n = 3000
    free_free = _tridiagonal(n, np.r_[1.0, np.full(n - 2, 2.0), 1.0], -1.0)
    indefinite = _tridiagonal(n, 1.0, -1.0)
    scene = _bad(tmp_path, 'M = "M.mtx"\nK = "K.mtx"', {
        "M.mtx": lambda path: scipy.io.mmwrite(path, scipy.sparse.eye(n, format="csr")),
        "K.mtx": lambda path: scipy.io.mmwrite(path, indefinite)})
    with pytest.raises(ScenarioError, match="system.K: expected a symmetric positive semi-definite matrix; K.mtx is "
                                            "not"):
        smdcli.load(scene)
    assert _factors(free_free, 1e-12 * 2 * n) and not _factors(indefinite, 1e-12 * 2 * n)
    small = 400  # above the dense-first size: the banded path, against the eigenvalues
    for matrix in (_tridiagonal(small, np.r_[1.0, np.full(small - 2, 2.0), 1.0], -1.0), _tridiagonal(small, 1.0, -1.0),
                   _tridiagonal(small, 2.0, -1.0)):
        lowest = scipy.linalg.eigvalsh(matrix.toarray())[0]
        assert _factors(matrix, 1e-12 * 2 * small) == (lowest > -1e-12 * 2 * small)


def test_a_large_non_diagonal_mass_is_refused_before_it_fills_memory(tmp_path, monkeypatch):
    """Above SPARSE_DOFS a non-diagonal M would be solved dense: refused, with why and how much, where that would not
    fit the limit (lowered here so a small scene shows it)."""
    monkeypatch.setattr(sparse_module, "SPARSE_DOFS", 2)
    monkeypatch.setattr(sparse_module, "DENSE_FILE_BYTES", 100)
    M = np.array([[2.0, 0.5, 0.0], [0.5, 2.0, 0.5], [0.0, 0.5, 1.0]])
    scene = _bad(tmp_path, 'M = "M.mtx"\nK = "K.mtx"', {"M.mtx": _mtx(M), "K.mtx": _mtx(np.eye(3))})
    with pytest.raises(ScenarioError, match=r"system.M: 3 DOFs would be solved with dense matrices \(0.0 GB\) because "
                                            r"M is not diagonal"):
        build(smdcli.load(scene))


def test_a_damping_ratio_swept_on_matrices_from_files_is_the_damped_oscillator(tmp_path, cli):
    """zeta on a 1-DOF [system] from files writes C inline beside the files' M and K: each member's free decay is
    x0 e^(-zeta w t) (cos wd t + zeta / sqrt(1 - zeta^2) sin wd t)."""
    for key, value in (("M", 2.0), ("K", 50.0)):
        scipy.io.mmwrite(tmp_path / f"{key}.mtx", scipy.sparse.coo_matrix([[value]]))
    scene = tmp_path / "one.toml"
    scene.write_text('[time]\nend = 5.0\nstep = 0.01\n[system]\nM = "M.mtx"\nK = "K.mtx"\nx0 = [0.1]\n')
    swept = cli("sweep", scene, "--param", "zeta", "--values", "0.05,0.2", "--keep", "full", "-o", tmp_path / "out",
                "--no-plots")
    assert swept.exit_code == 0, swept.output
    with h5py.File(tmp_path / "out" / "one_sweep.h5") as f:
        t, x = f["time"][()], f["displacement"][()][:, :, 0]
    w = 5.0
    for zeta, member in zip((0.05, 0.2), x):
        wd = w * math.sqrt(1 - zeta**2)
        closed = 0.1 * np.exp(-zeta * w * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))
        assert np.abs(member - closed).max() <= 1e-12
