"""smd ida: incremental dynamic analysis. A linear scene's curves are exact straight lines and its collapse
intensities the drift limit over the slope; an elastoplastic 1-DOF's collapse intensity agrees with an independent
search on DOP853 runs; the fractiles and the fragility follow their definitions; an interrupted campaign resumes
without computing a record twice; bad input is one line."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

import smdcli
from conftest import ROOT

SUITE = ROOT / "records" / "suite"
RECORDS = [SUITE / "record_01.AT2", SUITE / "record_05.V2", SUITE / "record_09.csv"]
LINEAR = """
[time]
end = 1.0
step = 0.01
[[mass]]
name = "m"
m = 1000.0
[[spring]]
connects = ["ground", "m"]
k = 4.0e5
[[damper]]
connects = ["ground", "m"]
c = 1000.0
[ground_motion]
quantity = "acceleration"
type = "table"
file = "{record}"
units = "g"
[building]
storey_heights = [3.0]
"""
PULSE_T = np.arange(0.0, 4.0, 0.01)
PULSE_A = np.sin(2 * np.pi * 1.5 * PULSE_T) * np.exp(-((PULSE_T - 1.5) / 0.8) ** 2) \
    + 0.4 * np.sin(2 * np.pi * 3.1 * PULSE_T) * np.exp(-((PULSE_T - 2.0) / 0.6) ** 2)
ELASTOPLASTIC = LINEAR.replace('k = 4.0e5', 'law = "elastoplastic"\nk = 1.0e5\nfy = 3000.0').replace(
    'units = "g"', 'units = "m/s^2"')


def campaign(cli, scene, out, *args):
    """Run smd ida with --json and return its summary and the HDF5 file's path."""
    ran = cli("ida", scene, "-o", out, "--json", "--no-plots", "--workers", "1", *args)
    assert ran.exit_code == 0, ran.output
    return json.loads(ran.output), next(out.glob("*_ida.h5"))


def test_a_linear_scene_s_curves_are_straight_and_its_collapse_exact(cli, tmp_path):
    """Three records (AT2, COSMOS, CSV), PGA against the drift ratio with a 1 % drift limit and --im-tolerance 1e-10:
    every record's EDP / IM is one number to 1e-10 (measured 1e-15: the scene is linear in the record's scale),
    and its collapse intensity the limit over that number to 1e-8 (measured 3e-11); the fractiles are numpy's
    percentiles of the records' straight lines read at each EDP level; the fragility the lognormal MLE of the
    collapse intensities."""
    from smdcli.analysis.fragility import from_collapse_intensities

    scene = tmp_path / "linear.toml"
    scene.write_text(LINEAR.format(record=RECORDS[2].as_posix()))
    summary, path = campaign(cli, scene, tmp_path / "out", *[a for r in RECORDS for a in ("--records", str(r))], "--im", "pga",
                             "--collapse", "drift=0.01", "--im-tolerance", "1e-10", "--runs", "3")
    assert summary["analyses"] == sum(r["runs"] for r in summary["records"])
    with h5py.File(path) as f:
        im, edp, collapsed = f["runs/im"][()], f["runs/edp"][()], f["runs/collapse"][()]
        collapse_im, levels = f["collapse_im"][()], f["fractiles/edp"][()]
        fractile = {q: f[f"fractiles/im_{q}"][()] for q in (16, 50, 84)}
        theta, beta = f["fragility/theta"][()], f["fragility/beta"][()]
        assert (f.attrs["im"], f.attrs["edp"], f.attrs["im_units"]) == ("pga", "max_drift_ratio", "m/s^2")
    slopes = []
    for r in range(3):
        standing = np.isfinite(edp[r]) & (collapsed[r] == 0)
        ratio = edp[r][standing] / im[r][standing]
        assert ratio.max() == pytest.approx(ratio.min(), rel=1e-10)
        slopes.append(ratio.mean())
        assert collapse_im[r] == pytest.approx(0.01 / ratio.mean(), rel=1e-8)
    assert levels[0] == 0 and levels[-1] == 0.01 and len(levels) == 50
    lines = np.array([levels / s for s in slopes])
    for q in (16, 50, 84):
        assert fractile[q] == pytest.approx(np.percentile(lines, q, axis=0), rel=1e-8, abs=1e-12)
    fitted = from_collapse_intensities(collapse_im)
    assert (theta, beta) == (fitted.theta, fitted.beta)


def test_an_elastoplastic_collapse_intensity_agrees_with_an_independent_search_on_dop853_runs(cli, tmp_path):
    """An elastoplastic 1-DOF under a made-up pulse, PGA against the drift ratio, collapse at 5 % drift: smd's
    collapse intensity (exact event-to-event runs, bisection to 1e-10) against the test's own search, the same
    doubling hunt then Brent's method on the drift less the limit, on DOP853 runs at rtol 1e-12, to 1e-6
    (measured 2.8e-11)."""
    from scipy.optimize import brentq

    record = tmp_path / "pulse.csv"
    record.write_text("time,acc\n" + "".join(f"{t:.2f},{float(a)!r}\n" for t, a in zip(PULSE_T, PULSE_A)))
    scene = tmp_path / "epp.toml"
    scene.write_text(ELASTOPLASTIC.format(record=record.as_posix()))
    _, path = campaign(cli, scene, tmp_path / "out", "--records", str(record), "--im", "pga", "--collapse",
                       "drift=0.05", "--im-tolerance", "1e-10", "--runs", "2", "--tail", "2")
    with h5py.File(path) as f:
        found = f["collapse_im"][0]
    pga = np.abs(PULSE_A).max()

    def drift(im: float) -> float:
        text = ELASTOPLASTIC.format(record=record.as_posix()).replace("end = 1.0", f"end = {float(PULSE_T[-1]) + 2.0!r}")
        text = text.replace('units = "m/s^2"', f'units = "m/s^2"\nscale = {float(im / pga)!r}')
        one = tmp_path / "one.toml"
        one.write_text(text)
        run = smdcli.simulate(one, method="DOP853", rtol=1e-12, atol=1e-14)
        return float(run.storeys.peak_drift_ratio.max())
    lo, im = 0.0, 0.25 * pga
    while drift(im) <= 0.05:
        lo, im = im, 2 * im
    reference = brentq(lambda x: drift(x) - 0.05, lo, im, xtol=1e-12, rtol=1e-13)
    assert found == pytest.approx(reference, rel=1e-6), (found, reference)


def test_an_interrupted_campaign_resumes_without_computing_a_record_twice(cli, tmp_path, monkeypatch):
    """A campaign stopped after two of three records keeps them in OUT/<stem>_ida.partial; --resume computes the
    third alone and writes what an undisturbed campaign writes."""
    import smdcli.commands.ida as ida

    scene = tmp_path / "linear.toml"
    scene.write_text(LINEAR.format(record=RECORDS[2].as_posix()))
    args = (*[a for r in RECORDS for a in ("--records", str(r))], "--im", "pga", "--collapse", "drift=0.01", "--runs", "2")
    _, undisturbed = campaign(cli, scene, tmp_path / "whole", *args)
    calls, real = [], ida.run_record

    def stopping(task):
        calls.append(task["record"])
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(task)
    monkeypatch.setattr(ida, "run_record", stopping)
    ran = cli("ida", scene, "-o", tmp_path / "out", "--no-plots", "--workers", "1", *args)
    assert ran.exit_code == 130, ran.output
    assert len(list((tmp_path / "out" / "linear_ida.partial").glob("*.json"))) == 2
    calls.clear()
    summary, resumed = campaign(cli, scene, tmp_path / "out", *args, "--resume")
    assert calls == [str(RECORDS[2])] and summary["resumed_records"] == 2
    with h5py.File(undisturbed) as a, h5py.File(resumed) as b:
        for name in ("runs/im", "runs/edp", "runs/collapse", "collapse_im", "fractiles/im_50", "fragility/theta"):
            assert np.array_equal(a[name][()], b[name][()], equal_nan=True), name
    assert not (tmp_path / "out" / "linear_ida.partial").exists()


@pytest.mark.parametrize("change,args,message", [
    ("", ("--edp", "residual_drift", "--im", "pgx"), "--im pgx"),
    ("[building]\nstorey_heights = [3.0]\n", ("--edp", "peak_displacement:m", "--collapse", "drift=0.01"),
     "needs a [building] table"),
    ("", ("--edp", "peak_displacement:x"), "expected peak_displacement:<dof>"),
    ("", ("--records", "nowhere"), "--records nowhere: no such file or folder"),
    ("", ("--records", "BAD"), "line 3"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(change, args, message, cli, tmp_path):
    """An unknown IM or EDP, a drift limit without storeys, a missing or malformed record: one line, exit 2, no
    output folder."""
    text = LINEAR.format(record=RECORDS[2].as_posix())
    if change:
        text = text.replace(change, "")
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    bad = tmp_path / "bad.AT2"
    bad.write_text("PEER\nX\nACCELERATION TIME SERIES IN UNITS OF FOO\nNPTS= 2, DT= .01 SEC\n1 2\n")
    args = tuple(str(bad) if a == "BAD" else a for a in args)
    if "--records" not in args:
        args += ("--records", str(RECORDS[2]))
    ran = cli("ida", scene, "-o", tmp_path / "out", *args)
    assert ran.exit_code == 2 and message in ran.output and len(ran.output.strip().splitlines()) == 1, ran.output
    assert not (tmp_path / "out").exists()


def test_the_ida_table_is_read_and_the_flags_override_it(cli, tmp_path):
    """[ida] records (relative to the scenario), im, edp, collapse, runs, im_tolerance, tail; a flag wins."""
    scene = tmp_path / "scene.toml"
    (tmp_path / "records").mkdir()
    (tmp_path / "records" / "one.csv").write_bytes(RECORDS[2].read_bytes())
    scene.write_text(LINEAR.format(record=RECORDS[2].as_posix()) + '\n[ida]\nrecords = "records"\nim = "pgv"\n'
                     'collapse = "drift=0.01"\nruns = 1\ntail = 1.0\n')
    summary, path = campaign(cli, scene, tmp_path / "out")
    assert summary["im"] == "pgv" and summary["collapse"] == "drift=0.01" and len(summary["records"]) == 1
    summary, _ = campaign(cli, scene, tmp_path / "out2", "--im", "pga")
    assert summary["im"] == "pga"


def test_a_dask_campaign_gives_the_process_pool_s_numbers(cli, tmp_path):
    """--scheduler local (a local Dask cluster, a record per task) writes the same runs and collapse intensities
    as the in-process campaign."""
    pytest.importorskip("dask.distributed")
    scene = tmp_path / "linear.toml"
    scene.write_text(LINEAR.format(record=RECORDS[2].as_posix()))
    args = (*[a for r in RECORDS[:2] for a in ("--records", str(r))], "--im", "pga", "--collapse", "drift=0.01",
            "--runs", "1")
    _, local = campaign(cli, scene, tmp_path / "local", *args)
    _, dask = campaign(cli, scene, tmp_path / "dask", *args, "--scheduler", "local")
    with h5py.File(local) as a, h5py.File(dask) as b:
        for name in ("runs/im", "runs/edp", "runs/collapse", "collapse_im"):
            assert np.array_equal(a[name][()], b[name][()], equal_nan=True), name


def test_a_dask_worker_killed_mid_campaign_changes_no_number(cli, tmp_path):
    """A campaign on a two-worker Dask cluster whose busy worker is killed (SIGKILL) as soon as it holds a record's
    task: Dask reruns the lost task elsewhere (a task is a pure function of its record and options), and the file
    equals the in-process campaign's."""
    import os
    import signal
    import threading
    import time

    pytest.importorskip("dask.distributed")
    from dask.distributed import Client, LocalCluster

    scene = tmp_path / "linear.toml"
    scene.write_text(LINEAR.format(record=RECORDS[2].as_posix()))
    args = (*[a for r in RECORDS for a in ("--records", str(r))], "--im", "pga", "--collapse", "drift=0.01",
            "--runs", "1")
    _, local = campaign(cli, scene, tmp_path / "local", *args)
    killed = []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        def kill_the_first_busy_worker():
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not killed:
                busy = [worker for worker, tasks in client.processing().items() if tasks]
                if busy:
                    pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
                    os.kill(pid, signal.SIGKILL)
                    killed.append(busy[0])
                time.sleep(0.02)
        killer = threading.Thread(target=kill_the_first_busy_worker)
        killer.start()
        _, survived = campaign(cli, scene, tmp_path / "dask", *args, "--scheduler", cluster.scheduler_address)
        killer.join()
    assert killed, "no worker was busy to kill"
    with h5py.File(local) as a, h5py.File(survived) as b:
        for name in ("runs/im", "runs/edp", "runs/collapse", "collapse_im", "fractiles/im_50", "fragility/theta"):
            assert np.array_equal(a[name][()], b[name][()], equal_nan=True), name
