"""Stated accuracies: every number smd writes says how accurately it is computed, and that is true.

Quantities that are ill-conditioned by nature are computed well-conditioned (a resonance peak as the zero of the
slope of |H|^2) or carry their true accuracy (a settling time next to the band's edge, a repeated mode's shape).
This file runs in CI again under other CPUs' BLAS and numba targets (.ci/run)."""

import math

import h5py
import mpmath
import numpy as np
import pytest
from conftest import SCENARIOS, bundled, model_of, one_dof

from smdcli.commands.diff import diff
from smdcli.model import time_grid
from smdcli.model.accuracy import evaluation_accuracy, modes_accuracy
from smdcli.scenario.spec import TimeSpec
from smdcli.sweep.members import measures

# ------------------------------------------------------------------------------------------- peaks


@pytest.mark.parametrize("zeta", [0.02, 0.05, 0.1, 0.3, 0.5, 0.7, 0.75])
def test_receptance_peaks_are_at_the_closed_form_frequency(zeta, tmp_path, cli):
    """|H| of a 1-DOF peaks at wn sqrt(1 - 2 zeta^2): found to rounding, not to sqrt(eps) as an argmax would."""
    wn, m = 7.0, 2.0
    text = one_dof(c=2 * zeta * wn * m, k=wn * wn * m, m=m) + '[[force]]\non = "m"\ntype = "sine"\namplitude = 1.0\n' \
        'omega = 1.0\n'
    scene = tmp_path / "r.toml"
    scene.write_text(text)
    assert cli("sweep", scene, "--frequency", "0.5:12:0.25", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    with h5py.File(tmp_path / "r_sweep.h5") as f:
        found = f["peaks/omega"][()]
        stated = f["peaks/omega"].attrs["stated_accuracy"]
    expected = wn * math.sqrt(1 - 2 * zeta**2) if zeta < math.sqrt(0.5) else None
    if expected is None:  # no peak for zeta >= 1/sqrt(2): |H| falls from w = 0
        assert len(found) == 0
        return
    assert len(found) == 1
    assert abs(found[0] - expected) <= stated * expected + 2e-16 * expected  # the closed form's own rounding
    assert stated < 1e-12


def test_transmissibility_peaks_are_at_the_closed_form_frequency(tmp_path, cli):
    """|X/U| of a base-excited 1-DOF peaks at r^2 = (sqrt(1 + 8 zeta^2) - 1) / (4 zeta^2) (Rao's closed form)."""
    assert cli("sweep", SCENARIOS / "transmissibility_1dof.toml", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    with h5py.File(tmp_path / "transmissibility_1dof_sweep.h5") as f:
        found, zeta = f["peaks/omega"][()], f["parameters/zeta"][()]
    r = np.sqrt((np.sqrt(1 + 8 * zeta**2) - 1) / (4 * zeta**2))
    np.testing.assert_allclose(found, 10.0 * r, rtol=4e-15)


def test_a_two_dof_peak_is_the_zero_of_the_slope_found_in_40_digits(tmp_path, cli):
    """Two DOFs: each located peak against the maximum of |H_j| found by mpmath at 40 digits."""
    assert cli("sweep", SCENARIOS / "two_dof_frequency_response.toml", "-o", tmp_path, "--no-plots",
               "-q").exit_code == 0
    sc, model, _ = bundled("two_dof_frequency_response")
    with h5py.File(tmp_path / "two_dof_frequency_response_sweep.h5") as f:
        omegas, dofs = f["peaks/omega"][()], [d.decode() for d in f["peaks/dof_name"][()]]
        stated = f["peaks/omega"].attrs["stated_accuracy"]
        top = float(np.abs(omegas).max())
        source = f.attrs["input_dof"]
        source = source.decode() if isinstance(source, bytes) else source
    mpmath.mp.dps = 40
    M, C, K = (mpmath.matrix(a.tolist()) for a in (model.M, model.C, model.K))
    b = mpmath.matrix([1 if d == source else 0 for d in model.dofs])

    def size(w, j):
        Z = K - w**2 * M + 1j * w * C
        return abs(mpmath.lu_solve(Z, b)[j]) ** 2

    for w, dof in zip(omegas, dofs):
        j = model.dofs.index(dof)
        exact = mpmath.findroot(lambda x: mpmath.diff(lambda y: size(y, j), x), mpmath.mpf(w))
        assert abs(w - float(exact)) <= stated * top, (dof, w, float(exact))
    assert stated < 1e-12


# ------------------------------------------------------------------------------- every data set


def _float_sets(path):
    found = {}
    with h5py.File(path) as f:
        f.visititems(lambda name, obj: found.__setitem__(name, dict(obj.attrs)) if isinstance(obj, h5py.Dataset)
                     and obj.dtype.kind == "f" else None)
    return found


@pytest.mark.parametrize("stem, kind", [("three_dof_forced", "simulate"), ("three_dof_matrix_forced", "simulate"),
                                        ("quarter_car_bump", "simulate"), ("one_dof_nonlinear_stiff", "simulate"),
                                        ("shear_frame_record", "simulate"), ("shear_frame_bilinear", "simulate"),
                                        ("one_dof_regimes_sweep", "sweep"),
                                        ("ic_underdamped", "sweep"), ("transmissibility_1dof", "sweep"),
                                        ("duffing_frequency_response", "sweep")])
def test_every_number_written_states_its_accuracy(stem, kind, tmp_path, cli):
    assert cli(kind, SCENARIOS / f"{stem}.toml", "-o", tmp_path, "--no-plots", "-q").exit_code == 0
    path = tmp_path / (f"{stem}.h5" if kind == "simulate" else f"{stem}_sweep.h5")
    for name, attrs in _float_sets(path).items():
        assert "stated_accuracy" in attrs, name
        value = float(attrs["stated_accuracy"])
        assert value >= 0 and not math.isnan(value), name
        if name.startswith("energy/"):  # measured by the largest energy the run reached
            assert attrs["accuracy_scale"] > 0, name


def test_modes_are_as_accurate_as_stated_against_40_digits():
    """The book's 3-DOF chain (not classically damped): natural frequencies sqrt(l1 l2) of the state matrix's
    eigenvalue pairs, and the undamped mass-normalized shapes, against mpmath's eigensolvers at 40 digits."""
    _, model, _ = bundled("three_dof_forced")
    accuracy = modes_accuracy(model)
    mpmath.mp.dps = 40
    n = model.n
    Minv = mpmath.matrix(model.M.tolist()) ** -1
    A = mpmath.zeros(2 * n, 2 * n)
    for i in range(n):
        A[i, n + i] = 1
    MK, MC = Minv * mpmath.matrix(model.K.tolist()), Minv * mpmath.matrix(model.C.tolist())
    for i in range(n):
        for j in range(n):
            A[n + i, j], A[n + i, n + j] = -MK[i, j], -MC[i, j]
    eigenvalues = mpmath.eig(A, left=False, right=False)
    w = np.sort([float(abs(lam)) for lam in eigenvalues if mpmath.im(lam) > 0])  # complex pairs: wn = |l|
    L = mpmath.cholesky(mpmath.matrix(model.M.tolist()))
    Linv = L ** -1
    squared, vectors = mpmath.eigsy(Linv * mpmath.matrix(model.K.tolist()) * Linv.T)
    order = sorted(range(n), key=lambda i: squared[i])
    shapes = np.array((Linv.T * vectors).tolist(), dtype=float)[:, order]
    shapes *= np.sign(shapes[np.argmax(np.abs(shapes), axis=0), np.arange(n)])  # smd's sign rule
    modes = model.modes
    assert np.abs(modes.natural_frequencies - w).max() <= accuracy["natural_frequencies_rad_s"] * w.max()
    assert np.abs(modes.shapes - shapes).max() <= accuracy["shapes"] * np.abs(shapes).max()
    assert accuracy["natural_frequencies_rad_s"] < 1e-12 and accuracy["shapes"] < 1e-11


def test_a_repeated_frequency_leaves_its_shapes_undetermined_and_says_so():
    """Two identical masses on identical springs to ground, uncoupled: any basis of the plane is a pair of modes."""
    text = """
[time]
end = 1.0
[[mass]]
name = "a"
m = 1.0
[[mass]]
name = "b"
m = 1.0
[[spring]]
connects = ["ground", "a"]
k = 4.0
[[spring]]
connects = ["ground", "b"]
k = 4.0
"""
    _, model, _ = model_of(text)
    accuracy = modes_accuracy(model)
    assert accuracy["shapes"] > 0.1  # not determined: a diff must not compare them
    assert accuracy["natural_frequencies_rad_s"] < 1e-13


def test_a_rigid_body_frequency_is_known_to_sqrt_eps():
    """A free-free pair: its zero frequency comes out of an eigenvalue near rounding, so to sqrt(eps) of the top."""
    text = """
[time]
end = 1.0
[[mass]]
name = "a"
m = 1.0
[[mass]]
name = "b"
m = 1.0
[[spring]]
connects = ["a", "b"]
k = 100.0
"""
    _, model, _ = model_of(text)
    accuracy = modes_accuracy(model)["natural_frequencies_rad_s"]
    rigid = float(model.modes.natural_frequencies.min())
    assert rigid <= accuracy * model.modes.natural_frequencies.max()
    assert 1e-10 < accuracy < 1e-5


def test_a_force_is_as_accurate_as_stated_against_40_digits():
    """F = 20 sin(120 t) on 0..20 s: its argument reaches 2400 rad, whose rounding the stated accuracy carries."""
    sc, model, grid = bundled("three_dof_forced")
    stated = evaluation_accuracy(model.applied_force, grid)
    mpmath.mp.dps = 40
    exact = np.array([float(20 * mpmath.sin(120 * mpmath.mpf(float(t)))) for t in grid])
    computed = model.applied_force(grid)[:, 0]
    error = np.abs(computed - exact).max() / np.abs(exact).max()
    assert error <= stated
    assert stated < 1e-10  # eps times the largest argument, 2400 rad, with its margin


def test_a_settling_time_next_to_the_band_carries_that_uncertainty():
    """A response whose late lobe just touches the 2 % band: within x's error the settling time may jump a lobe."""
    t = np.linspace(0.0, 10.0, 1001)
    x = np.exp(-0.5 * t) * np.cos(2 * np.pi * t)
    deviation = np.abs(x - x[-1])
    band = 0.02 * deviation.max()
    k = int(np.flatnonzero(deviation > band)[-1])  # the last sample outside: put it exactly on the edge
    x[k] = x[-1] + np.sign(x[k] - x[-1]) * band * (1 + 1e-10)
    X = x[None, None, :]
    far = measures(t, X, np.zeros_like(X), len(t), np.array([1e-15]))
    near = measures(t, X, np.zeros_like(X), len(t), np.array([1e-6]))
    assert far["settling_time_error"][0, 0] == 0.0
    assert near["settling_time_error"][0, 0] >= t[k + 1] - t[k]  # the edge sample may fall inside
    moved = X.copy()
    moved[0, 0, k] = x[-1] + np.sign(x[k] - x[-1]) * band * (1 - 1e-9)
    shifted = measures(t, moved, np.zeros_like(X), len(t))["settling_time"][0, 0]
    assert abs(shifted - near["settling_time"][0, 0]) <= near["settling_time_error"][0, 0]


# ------------------------------------------------------------------------------------------ grids


@pytest.mark.parametrize("start, end, step, last", [(0.0, 0.3, 0.1, 0.3), (0.0, 1.0, 0.3, 0.9),
                                                    (0.5, 1.7, 0.05, 1.7), (0.0, 20.0, 0.01, 20.0)])
def test_output_times_are_the_decimal_grid_rounded_once(start, end, step, last):
    grid = time_grid(TimeSpec(start=start, end=end, step=step))
    assert grid[-1] == last
    from fractions import Fraction

    for k in (1, len(grid) // 2, len(grid) - 1):
        assert grid[k] == float(Fraction(repr(start)) + k * Fraction(repr(step)))


# ------------------------------------------------------------------------------------------- diff


def test_diff_within_stated_uses_the_scale_and_ignores_what_is_not_determined(tmp_path):
    def write(path, residual, shapes):
        with h5py.File(path, "w") as f:
            f.attrs["smd_version"], f.attrs["kind"] = "0", "simulate"
            r = f.create_dataset("energy/residual", data=residual)
            r.attrs["stated_accuracy"], r.attrs["accuracy_scale"] = 1e-12, 10.0
            s = f.create_dataset("shapes", data=shapes)
            s.attrs["stated_accuracy"] = np.inf

    write(tmp_path / "a.h5", np.array([0.0, 1e-12]), np.array([1.0, 0.0]))
    write(tmp_path / "b.h5", np.array([0.0, 1.5e-11]), np.array([0.0, 1.0]))  # 1.4e-11 < 2e-12 * 10: same
    assert not diff(tmp_path / "a.h5", tmp_path / "b.h5", stated=True).differs
    write(tmp_path / "c.h5", np.array([0.0, 5e-11]), np.array([0.0, 1.0]))
    report = diff(tmp_path / "a.h5", tmp_path / "c.h5", stated=True)
    assert [d.name for d in report.datasets if d.status != "same"] == ["energy/residual"]


# ------------------------------------------------------------------------------------------- adaptive methods


def cubic_chain(n: int) -> str:
    """n masses of 1 kg, 100 N/m links, a cubic spring (k3 1000 N/m^3) and a 0.5 N s/m damper to the ground on the
    first, 10 sin 5t on it, 10 s: a wave that moves a few tens of the masses, the rest at rest."""
    from test_large import chain

    return chain(n, cubic=True, dampers="first", end=10.0, step=0.01)


@pytest.mark.parametrize("method", ["DOP853", "RK45"])
@pytest.mark.parametrize("rtol, atol", [(1e-8, 1e-16), (1e-10, None)], ids=["rtol", "atol"])
def test_an_adaptive_method_s_stated_accuracy_covers_a_long_chain(method, rtol, atol):
    """The error norm of scipy's step control (and the compiled kernels') is the root mean square over the state's
    components, so one moving mass among many at rest may err sqrt(2 n) times the tolerance, and atol adds up over
    the steps as rtol does: 10 rtol + atol / peak was exceeded 1.5x (DOP853, rtol 1e-8) to 20x (RK45, rtol 1e-10
    with the default atol 1e-9) on this 100-mass chain. x and v against the Taylor series at rtol 1e-13 (its own
    error about 1e-12 of the peak)."""
    import smdcli
    from smdcli.scenario import parse

    sc = parse(cubic_chain(100), "chain.toml")
    reference = smdcli.simulate(sc, method="taylor", rtol=1e-13)
    run = smdcli.simulate(sc, method=method, rtol=rtol, atol=atol)
    stated = run.stats.stated_accuracy
    for quantity in ("displacement", "velocity"):
        want = getattr(reference, quantity)
        error = np.abs(getattr(run, quantity) - want).max() / np.abs(want).max()
        assert error <= stated, (quantity, error, stated)
    assert stated < 30 * math.sqrt(200) * (rtol + (atol or 1e-9) / np.abs(reference.displacement).max())


@pytest.mark.parametrize("method", ["ode23", "ode23s", "ode23t", "ode23tb", "ode15s", "ode113", "LSODA"])
def test_a_low_order_method_s_stated_accuracy_is_measured_and_covers_its_error(method):
    """At rtol 1e-8 a second-order method's global error outgrows any multiple of the tolerance a statement could
    assume (ode23t 2.1e-5 of the peak on this 3-mass chain, where 10 sqrt(2n) rtol said 2.4e-7), as a variable-order
    one's does where it runs at its low orders (ode113 3x at rtol 1e-10 on a 30-mass chain): its error is measured
    by a rerun at a tenth of the tolerance, covers x and v against the Taylor series at rtol 1e-13, and says so; and
    the statement stays within a few times the error (the rerun's difference, not a bound that says nothing)."""
    import smdcli
    from smdcli.scenario import parse

    sc = parse(cubic_chain(3), "chain.toml")
    reference = smdcli.simulate(sc, method="taylor", rtol=1e-13)
    run = smdcli.simulate(sc, method=method, rtol=1e-8, atol=1e-16)
    stated = run.stats.stated_accuracy
    errors = [np.abs(getattr(run, q) - getattr(reference, q)).max() / np.abs(getattr(reference, q)).max()
              for q in ("displacement", "velocity")]
    assert max(errors) <= stated, (errors, stated)
    assert stated <= 10 * max(errors)
    if stated > 10 * math.sqrt(6) * 1e-8 * 1.001:  # above the tolerance's statement: a note says it was measured
        assert any("low-order method's global error" in note for note in run.notes), run.notes
