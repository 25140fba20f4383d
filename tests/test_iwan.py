"""The Iwan spring (`law = "iwan"`): N elastic-perfectly-plastic elements in one table, against the same N as
`elastoplastic` springs (every method), its multilinear backbone in closed form, Masing's unloading, its energy
balance, its input checks, a sweep of one element's yield force and compare-solvers' verdicts."""

import json

import numpy as np
import pytest
from conftest import model_of

from smdcli.solvers import solve
from smdcli.solvers.base import Tolerances

K, FY = (300.0, 200.0, 100.0), (3.0, 6.0, 9.0)


def scene(iwan: bool, x0: float = 0.05, extra: str = "", two_dof: bool = False) -> str:
    """A mass (or two, the Iwan spring between them) on the spring, damped and driven; with `iwan` false the
    spring is written as its elements, elastoplastic springs in parallel."""
    a, b = ("m1", "m2") if two_dof else ("ground", "m1")
    text = f"[time]\nend = 3.0\nstep = 0.01\n[[mass]]\nname = \"m1\"\nm = 1.0\nx0 = {x0!r}\n"
    if two_dof:
        text += ('[[mass]]\nname = "m2"\nm = 0.7\n[[spring]]\nconnects = ["ground", "m1"]\nk = 150.0\n'
                 '[[damper]]\nconnects = ["ground", "m2"]\nc = 0.2\n')
    if iwan:
        text += f'[[spring]]\nconnects = ["{a}", "{b}"]\nlaw = "iwan"\nk = {list(K)!r}\nfy = {list(FY)!r}\n'
    else:
        text += "".join(f'[[spring]]\nconnects = ["{a}", "{b}"]\nlaw = "elastoplastic"\nk = {k!r}\nfy = {fy!r}\n'
                        for k, fy in zip(K, FY))
    text += '[[damper]]\nconnects = ["ground", "m1"]\nc = 0.3\n'
    return text + (extra or '[[force]]\non = "m1"\ntype = "sine"\namplitude = 12.0\nomega = 9.0\n')


RECORD = ('[ground_motion]\nquantity = "acceleration"\ntype = "table"\nt = [0.0, 0.2, 0.5, 0.9, 1.3]\n'
          'values = [0.0, 25.0, -30.0, 18.0, 0.0]\n')
CASES = {"sine": {}, "from rest under a record": {"x0": 0.0, "extra": RECORD},
         "between two masses": {"two_dof": True},
         "shock pulse": {"x0": 0.0, "extra": ('[[force]]\non = "m1"\ntype = "pulse"\nshape = "half_sine"\n'
                                              'amplitude = 40.0\nt0 = 0.1\nduration = 0.2\n')}}


def relative(a, b) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("case", CASES)
def test_exact_equals_its_elements_as_parallel_elastoplastic_springs_to_rounding(case):
    _, iwan, grid = model_of(scene(True, **CASES[case]))
    _, parallel, _ = model_of(scene(False, **CASES[case]))
    a = solve(iwan, grid, "exact", Tolerances())
    b = solve(parallel, grid, "exact", Tolerances())
    assert relative(a.displacement, b.displacement) <= 1e-12
    assert relative(a.velocity, b.velocity) <= 1e-12
    force = a.nonsmooth.tension[:, 0]
    parts = b.nonsmooth.tension[:, :3].sum(axis=1)
    assert np.abs(force - parts).max() <= 1e-12 * np.abs(parts).max()
    first = 1 if case == "between two masses" else 0  # there a linear spring comes first
    for i in range(3):  # each element's plastic deformation is its elastoplastic twin's
        mine = a.nonsmooth.internal[f"spring[{first}].plastic_deformation_{i + 1}"]
        twin = b.nonsmooth.internal[f"spring[{first + i}].plastic_deformation"]
        assert np.abs(mine - twin).max() <= 1e-12 * max(np.abs(twin).max(), 1e-3)
    assert a.nonsmooth.balance().max_relative_residual <= 1e-10
    assert sum(kind == "yield" for _, _, kind in a.nonsmooth.events) >= 3


@pytest.mark.parametrize("method, tolerance", [("DOP853", 1e-7), ("Radau", 1e-6), ("newmark", 1e-12),
                                               ("hht", 1e-12)])
def test_every_method_steps_it_as_it_steps_the_parallel_springs(method, tolerance):
    """Integrators locate the same events (to their tolerance: event times differ by rounding, which their
    error control then carries); the Newmark family return-maps each element as the twin's own spring."""
    _, iwan, grid = model_of(scene(True))
    _, parallel, _ = model_of(scene(False))
    tol = Tolerances(rtol=1e-10, atol=1e-13) if method in ("DOP853", "Radau") else Tolerances(dt=0.002)
    a, b = solve(iwan, grid, method, tol), solve(parallel, grid, method, tol)
    assert a.success and b.success
    assert relative(a.displacement, b.displacement) <= tolerance
    exact = solve(iwan, grid, "exact", Tolerances())
    assert relative(a.displacement, exact.displacement) <= (1e-7 if method in ("DOP853", "Radau") else 1e-2)


def test_the_backbone_is_multilinear_and_unloading_follows_masing():
    """From rest under a growing force the force-deformation curve is sum_i min(k_i |d|, fy_i) (the backbone);
    after the first reversal at (d_r, F_r), F = F_r - 2 B((d_r - d) / 2) (Masing: the backbone doubled)."""
    ramp = '[[force]]\non = "m1"\ntype = "table"\nt = [0.0, 2.0, 3.0]\nvalues = [0.0, 24.0, -24.0]\n'
    text = scene(True, x0=0.0, extra=ramp).replace('c = 0.3', 'c = 30.0').replace("m = 1.0", "m = 0.01")
    _, model, grid = model_of(text)
    reversal = next(t for t, _, kind in solve(model, grid, "exact", Tolerances()).nonsmooth.events if kind == "unload")
    grid = np.union1d(grid, [reversal])  # the turning point itself sampled
    run = solve(model, grid, "exact", Tolerances())
    d, force = run.displacement[:, 0], run.nonsmooth.tension[:, 0]

    def backbone(x):
        return sum(np.sign(x) * np.minimum(k * np.abs(x), fy) for k, fy in zip(K, FY))

    turn = int(np.searchsorted(grid, reversal))
    assert d[turn] == d.max()
    assert d[turn] > FY[-1] / K[-1]  # past every element's yield
    assert np.abs(force[:turn] - backbone(d[:turn])).max() <= 1e-12 * sum(FY)
    after = slice(turn, len(d))
    masing = force[turn] - 2 * backbone((d[turn] - d[after]) / 2)
    assert np.abs(force[after] - masing).max() <= 1e-10 * sum(FY)


@pytest.mark.parametrize("field, value, message", [
    ("fy", [3.0, 6.0], "spring[0].fy: expected 3 yield forces (one per entry of k), found 2"),
    ("k", [300.0, -1.0, 100.0], "spring[0].k[1]: expected a positive number, found -1"),
    ("k", 300.0, "spring[0].k: expected an array of numbers"),
])
def test_bad_arrays_are_refused_with_one_line(tmp_path, cli, field, value, message):
    text = scene(True).replace(f"{field} = {list(K if field == 'k' else FY)!r}", f"{field} = {value!r}")
    path = tmp_path / "bad.toml"
    path.write_text(text)
    ran = cli("simulate", path, "--no-plots", "-o", tmp_path / "out")
    assert ran.exit_code == 2, ran.output
    assert message in ran.stderr
    assert not (tmp_path / "out").exists()


def test_a_sweep_varies_one_elements_yield_force(tmp_path, cli):
    """spring[0].fy[1] swept: each member equals simulate of its scenario."""
    import h5py

    path = tmp_path / "iwan.toml"
    path.write_text(scene(True) + '[sweep]\nparameter = "spring[0].fy[1]"\nvalues = [2.0, 6.0, 12.0]\n')
    ran = cli("sweep", path, "--no-plots", "-o", tmp_path / "out")
    assert ran.exit_code == 0, ran.output
    with h5py.File(tmp_path / "out" / "iwan_sweep.h5") as f:
        x = f["displacement"][()]
    for member, fy in enumerate((2.0, 6.0, 12.0)):
        _, model, grid = model_of(scene(True).replace("fy = [3.0, 6.0, 9.0]", f"fy = [3.0, {fy!r}, 9.0]"))
        alone = solve(model, grid, "exact", Tolerances()).displacement
        assert relative(x[member], alone) <= 1e-12
    assert relative(x[0], x[2]) > 0.1  # the parameter did something


def test_compare_solvers_charts_it_and_judges_the_newmark_family_by_its_error(tmp_path, cli):
    path = tmp_path / "iwan.toml"
    path.write_text(scene(True))
    ran = cli("compare-solvers", path, "--methods", "DOP853,newmark", "-o", tmp_path / "out", "--json")
    assert ran.exit_code == 0, ran.output
    rows = json.loads(ran.stdout)["runs"]
    newmark = [r for r in rows if r["method"] == "newmark"]
    assert newmark and all(r["success"] for r in newmark), [r["message"] for r in newmark]
    errors = [r["error"] for r in newmark]
    assert errors[-1] < 1e-3 and errors[-1] < errors[0]  # second order: finer steps, smaller error
    assert all(r["success"] for r in rows if r["method"] == "DOP853")
    assert (tmp_path / "out" / "iwan_work_precision.png").exists()
