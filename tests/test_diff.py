"""smd diff: what differs, where, and the exit code; run metadata never counts."""

import json
import shutil

import h5py
import numpy as np
import pytest
from conftest import ROOT, SCENARIOS

GOLDEN = ROOT / "tests" / "golden"
ALL_GOLDENS = sorted(GOLDEN.glob("*.h5")) + sorted((GOLDEN / "sweep").glob("*.h5"))


def float_datasets(path):
    names = []
    with h5py.File(path) as f:
        f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) and o.dtype.kind == "f"
                     and np.any(np.nan_to_num(o[()], posinf=0, neginf=0) != 0) else None)
    return names


@pytest.mark.parametrize("golden", ALL_GOLDENS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_one_part_in_a_million_in_one_sample_is_caught(cli, tmp_path, golden):
    same = tmp_path / "same.h5"
    shutil.copy(golden, same)
    result = cli("diff", golden, same)
    assert result.exit_code == 0, result.output
    rng = np.random.default_rng(abs(hash(golden.name)) % 2**32)
    for name in float_datasets(golden)[:6]:
        changed = tmp_path / f"changed_{name.replace('/', '_')}.h5"
        shutil.copy(golden, changed)
        with h5py.File(changed, "r+") as f:
            data = f[name][()]
            nonzero = np.flatnonzero(np.isfinite(data) & (data != 0))
            index = np.unravel_index(rng.choice(nonzero), data.shape)
            data[index] *= 1 + 1e-6
            f[name][...] = data
        result = cli("diff", golden, changed)
        assert result.exit_code == 1, (name, result.output)
        assert f"/{name} " in result.stdout and "1 of" in result.stdout


def simulate(cli, out, *extra, name="two_dof_forced"):
    result = cli("simulate", SCENARIOS / f"{name}.toml", "-o", out, "--no-plots", *extra)
    assert result.exit_code in (0, 1), result.output
    return out / f"{name}.h5"


def test_reports_where_and_how_much(cli, tmp_path):
    a = simulate(cli, tmp_path / "a")
    b = tmp_path / "b.h5"
    shutil.copy(a, b)
    with h5py.File(b, "r+") as f:
        f["velocity"][700, 1] += 0.25
        f["acceleration"][10:20, 0] *= 2
        del f["force"]
        f.attrs["created"] = "2000-01-01T00:00:00+00:00"  # run metadata: never a difference
        f["solver"].attrs["wall_time_s"] = 99.0
    result = cli("diff", a, b, "--json")
    assert result.exit_code == 1
    report = {d["name"]: d for d in json.loads(result.stdout)["datasets"]}
    velocity = report["velocity"]
    assert velocity["status"] == "different" and velocity["count"] == 1
    assert velocity["largest"] == pytest.approx(0.25)
    assert velocity["where"] == {"time": pytest.approx(3.5), "dof": "m2"}
    assert report["acceleration"]["count"] == 10
    assert report["force"]["status"] == "only in A"
    assert report["displacement"]["status"] == "same"
    text = cli("diff", a, b).stdout
    assert "at time = 3.5, dof = m2" in text and "/force: only in" in text


def test_grids_scenarios_and_solvers_are_named(cli, tmp_path):
    a = simulate(cli, tmp_path / "a")
    b = simulate(cli, tmp_path / "b", "--method", "RK45")
    result = cli("diff", a, b, "--rtol", "1e-3", "--atol", "1e-3")
    assert result.exit_code == 0, result.output
    assert "note: different solver method: exact vs RK45" in result.stdout
    text = (SCENARIOS / "two_dof_forced.toml").read_text().replace("step = 0.005", "step = 0.01")
    (tmp_path / "two_dof_forced.toml").write_text(text)
    result = cli("simulate", tmp_path / "two_dof_forced.toml", "-o", tmp_path / "c", "--no-plots")
    assert result.exit_code == 0
    result = cli("diff", a, tmp_path / "c" / "two_dof_forced.h5")
    assert result.exit_code == 1
    assert "/time: different time grids: different shapes (1001,) vs (501,)" in result.stdout
    assert "note: different scenario (sha256" in result.stdout
    result = cli("diff", a, tmp_path / "c" / "two_dof_forced.h5", "--datasets", "dof,model/M")
    assert result.exit_code == 0, result.output


def test_unreadable_or_foreign_files_are_exit_2(cli, tmp_path):
    a = simulate(cli, tmp_path / "a")
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = [1.0]
    (tmp_path / "text.h5").write_text("not hdf5")
    for other, message in ((foreign, "not one smd wrote"), (tmp_path / "text.h5", "not a readable HDF5 file"),
                           (tmp_path / "missing.h5", "no such file"), (tmp_path, "is a directory")):
        result = cli("diff", a, other)
        assert result.exit_code == 2 and message in result.stderr, result.output
        assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.output
    result = cli("diff", a, a, "--datasets", "nonsense")
    assert result.exit_code == 2 and "--datasets" in result.stderr


def test_a_failed_run_is_refused_unless_allowed(cli, tmp_path):
    text = (SCENARIOS / "one_dof_undamped.toml").read_text() + '\n[solver]\nmethod = "central_difference"\ndt = 0.5\n'
    (tmp_path / "unstable.toml").write_text(text.replace("end = 5.0", "end = 200.0"))
    result = cli("simulate", tmp_path / "unstable.toml", "-o", tmp_path / "b", "--no-plots", "--save-partial")
    assert result.exit_code == 1 and "marked failed" in result.stderr
    failed = tmp_path / "b" / "unstable_partial.h5"
    assert not (tmp_path / "b" / "unstable.h5").exists()
    with h5py.File(failed) as f:
        assert not f["solver"].attrs["success"] and f["solver"].attrs["t_failed"] > 0
        x = f["displacement"][()]
        reached = f["time"][()] <= f["solver"].attrs["t_failed"]
        assert np.isfinite(x[reached]).all() and np.isnan(x[~reached]).all()
    good = tmp_path / "good.h5"
    shutil.copy(failed, good)
    with h5py.File(good, "r+") as f:
        f["solver"].attrs["success"] = True
    result = cli("diff", good, failed)
    assert result.exit_code == 2 and "--allow-failed" in result.stderr
    result = cli("diff", good, failed, "--allow-failed")
    assert result.exit_code == 0 and "its run failed" in result.stdout  # the same data, and the failure named
    with h5py.File(good, "r+") as f:
        f["displacement"][0, 0] += 1.0
    assert cli("diff", good, failed, "--allow-failed").exit_code == 1


@pytest.mark.parametrize("command", [
    ["compare-solvers", SCENARIOS / "one_dof_underdamped.toml", "--methods", "ode45,rk4", "--tolerances", "1e-4,1e-6",
     "--steps", "0.05,0.01", "--repeats", "1"],
    ["sweep", SCENARIOS / "one_dof_nonlinear_stiff.toml", "--param", "damper[0].c", "--values", "500,1001",
     "--workers", "2"],
    ["phase", SCENARIOS / "one_dof_square_wave.toml", "--poincare"],
])
def test_every_kind_of_file_is_deterministic_and_diffable(cli, tmp_path, command):
    for out in ("a", "b"):
        result = cli(*command, "-o", tmp_path / out, "--no-plots" if command[0] != "phase" else "--quiet")
        assert result.exit_code == 0, result.output
    (name,) = [p.name for p in (tmp_path / "a").glob("*.h5")]
    result = cli("diff", tmp_path / "a" / name, tmp_path / "b" / name, "--rtol", "0")
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "b" / name, "r+") as f:
        target = next(n for n in float_datasets(tmp_path / "b" / name) if "wall_time" not in n)
        f[target][...] = f[target][()] * 1.001
    assert cli("diff", tmp_path / "a" / name, tmp_path / "b" / name).exit_code == 1
