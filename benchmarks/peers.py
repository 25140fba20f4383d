"""The peers a user would pick instead, on the same inputs as smd, in one process where they run in Python: time
(median of repeats; on the spectra and the nonlinear scenes smd's runs are split before and after its peers') and
error of each, in one table. Peers that are not installed are skipped with a line
(pip install -e '.[peers]': openseespy, eqsig, pyrotd, python-control; scipy is always there).

    python benchmarks/peers.py [--repeats 7]

Work compared:
- response spectrum, 200 periods (0.02 to 10 s), 5 %, of a 4,001-sample record (the synthetic recipe, 40 s at
  100 Hz): smd (exact, peaks located between samples) against eqsig's Nigam-Jennings pseudo spectra and pyrotd;
  error: the largest |Sa - Sa_ref| over all periods for smd, from 6 dt up for the peers (eqsig gives the PGA below),
  over the largest Sa_ref, the reference being scipy's lsim (exact for the linearly interpolated record) on a grid
  50 times finer than the record, each peak the largest of the quintic through y, y' and y'' on the fine steps
  beside the largest sample (within 1e-13 of smd's at every period; 25 times finer: 6e-13 at the shortest);
- a linear 3-DOF forced response (three_dof_forced, 0..120 s, 12,001 points): smd exact against
  python-control's forced_response and scipy's solve_ivp RK45 (rtol 1e-6); error: largest displacement
  difference from DOP853 at rtol 1e-12, over the peak;
- linear chains of 1,000 and 10,000 masses, 1,001 output points: smd's `auto` (exact at 1,000, the Taylor series on
  the sparse rows at 10,000) against OpenSees (Newmark, banded), and the whole `smd simulate` of the 10,000; error of both
  against the dense state transition of the 1,000 (one expm of the whole augmented system, stepped);
- an elastoplastic 1-DOF under the record: smd exact against OpenSees ElasticPP at dt / 16 (from
  benchmarks/elastoplastic_vs_opensees.py); error against smd's event-driven Radau at rtol 1e-11;
- nonlinear scenes at the same error: the book's stiff damper (one_dof_nonlinear_stiff, c |v| v, 20,001 points) and
  chains of 10, 100 and 1,000 masses with a cubic first spring and a sine force (compiled_vs_solve_ivp.chain,
  1,001 points): smd's `auto` at the scene's settings against scipy's solve_ivp DOP853, RK45 and Radau (its
  analytic Jacobian, sparse for chains) on the right-hand side a user would write in numpy, each at the loosest
  rtol (10^-3 to 10^-13 in half decades, atol 1e-3 rtol times the peak) whose error is no larger than smd's;
  error: the largest displacement difference from scipy DOP853 at rtol 1e-13, over the peak.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import textwrap
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "records"))
sys.path.insert(0, str(ROOT / "benchmarks"))
G = 9.80665


def timed(fn, repeats: int):
    """(median seconds, last result): compiled_vs_solve_ivp's median_time."""
    from compiled_vs_solve_ivp import median_time

    return median_time(fn, repeats)


def timed_around(fn, repeats: int, peers):
    """(median seconds, last result) of fn run `repeats` times before the peers' runs and as many after, with what
    `peers()` returns: smd timed over the same stretch of time as its peers, so that a slow spell of a shared machine
    does not fall on one side only."""
    import statistics

    from compiled_vs_solve_ivp import run_times

    before, _ = run_times(fn, repeats)
    found = peers()
    after, out = run_times(fn, repeats)
    return statistics.median(before + after), out, found


def installed(name: str) -> bool:
    return importlib.util.find_spec(name) is not None


def quintic_peak(h, start, end):
    """The largest |y| on a step of length h of the quintic through y, y' and y'' at its two ends (start and end:
    (y, v, a) each): within (w h)^6 / 46,080 of the true |y| for a motion of circular frequency w."""
    (y0, v0, a0), (y1, v1, a1) = start, end
    # p(s) = y0 + v0 h s + a0 h^2 s^2 / 2 + c3 s^3 + c4 s^4 + c5 s^5 on s in [0, 1], matching y1, h v1 and h^2 a1
    low = np.array([y0, v0 * h, a0 * h * h / 2])
    rhs = np.array([y1 - low.sum(), h * v1 - low[1] - 2 * low[2], h * h * a1 - 2 * low[2]])
    c3, c4, c5 = np.linalg.solve([[1.0, 1.0, 1.0], [3.0, 4.0, 5.0], [6.0, 12.0, 20.0]], rhs)
    poly = np.polynomial.Polynomial([*low, c3, c4, c5])
    turns = [r.real for r in poly.deriv().roots() if abs(r.imag) < 1e-12 and 0.0 <= r.real <= 1.0]
    return max(abs(poly(s)) for s in [0.0, 1.0, *turns])


def lsim_reference(t, a, periods, zeta, finer=50):
    """Sa of the record taken as straight lines between its samples, exact to about 1e-12: scipy's lsim (exact for
    such an input) gives y and y' on a grid `finer` times finer, the equation of motion y'', and each peak is the
    largest of the quintic through y, y' and y'' on the two fine steps beside the largest sample."""
    from scipy.signal import lsim

    fine = np.linspace(t[0], t[-1], (len(t) - 1) * finer + 1)
    h = fine[1] - fine[0]
    u = np.interp(fine, t, a)
    out = []
    for T in periods:
        w = 2 * math.pi / T
        system = ([[0.0, 1.0], [-w * w, -2 * zeta * w]], [[0.0], [-1.0]], [[1.0, 0.0]], [[0.0]])
        _, _, x = lsim(system, u, fine)
        y, v = x[:, 0], x[:, 1]
        acc = -w * w * y - 2 * zeta * w * v - u
        i = int(np.argmax(np.abs(y)))
        steps = [(j, j + 1) for j in (i - 1, i) if 0 <= j and j + 1 < len(y)]
        peak = max(quintic_peak(h, (y[j], v[j], acc[j]), (y[k], v[k], acc[k])) for j, k in steps)
        out.append(w * w * peak)
    return np.array(out)


def spectrum_rows(repeats):
    import make_synthetic

    from smdcli.analysis.spectrum import response_spectrum

    make_synthetic.DURATION_S = 40.0
    t, a_g = make_synthetic.synthetic_record()
    a = a_g * G
    dt = float(t[1] - t[0])
    periods = np.logspace(math.log10(0.02), 1, 200)
    reference = lsim_reference(t, a, periods, 0.05)
    response_spectrum(t, a, periods[:2], [0.05])  # kernels loaded
    # eqsig returns the PGA for periods below 6 dt (its convention): errors are taken over the others
    kept = periods >= 6 * dt

    def error(sa, over=kept):
        return np.abs(np.asarray(sa)[over] - reference[over]).max() / reference.max()

    def peers():
        found = []
        if installed("eqsig"):
            import eqsig

            eqsig.sdof.pseudo_response_spectra(a, dt, periods[:2], 0.05)
            s, (_, _, sa) = timed(lambda: eqsig.sdof.pseudo_response_spectra(a, dt, periods, 0.05), repeats)
            found.append(("eqsig 1.2 (Nigam-Jennings)", (s, error(sa))))
        else:
            found.append(("eqsig: not installed", None))
        if installed("pyrotd"):
            import pyrotd

            s, sa = timed(lambda: pyrotd.calc_spec_accels(dt, a, 1 / periods, 0.05), repeats)
            sa = np.asarray(sa.spec_accel if hasattr(sa, "spec_accel") else sa)
            found.append(("pyrotd 0.6 (frequency domain)", (s, error(sa))))
        else:
            found.append(("pyrotd: not installed", None))
        return found

    seconds, spectrum, found = timed_around(lambda: response_spectrum(t, a, periods, [0.05]), repeats, peers)
    smd = (seconds, error(spectrum.Sa[0], slice(None)))  # every period
    work = f"response spectrum, {len(t)} samples, 200 periods, 5 %"
    return [(work, smd, peer, result) for peer, result in found]


def linear_rows(repeats):
    from scipy.integrate import solve_ivp

    from smdcli import scenario
    from smdcli.model import build, time_grid
    from smdcli.solvers import solve
    from smdcli.solvers.base import Tolerances

    sc = scenario.load(ROOT / "scenarios" / "three_dof_forced.toml")
    model = build(sc)
    grid = time_grid(sc.time)
    y0 = np.concatenate([model.x0, model.v0])

    def rhs(t, y):
        return model.state_matrix @ y + model.input_matrix @ model.forces(t)

    ref = solve_ivp(rhs, (grid[0], grid[-1]), y0, method="DOP853", t_eval=grid, rtol=1e-12, atol=1e-14).y[:3].T
    peak = np.abs(ref).max()
    seconds, found = timed(lambda: solve(model, grid, "exact", Tolerances()).displacement, repeats)
    smd = (seconds, np.abs(found - ref).max() / peak)
    work = "linear 3-DOF forced response, 12,001 points"
    rows = []
    s, y = timed(lambda: solve_ivp(rhs, (grid[0], grid[-1]), y0, method="RK45", t_eval=grid, rtol=1e-6,
                                   atol=1e-9).y[:3].T, 1)
    rows.append((work, smd, "scipy solve_ivp RK45, rtol 1e-6", (s, np.abs(y - ref).max() / peak)))
    if installed("control"):
        import control

        n = model.n
        system = control.ss(model.state_matrix, model.input_matrix, np.hstack([np.eye(n), np.zeros((n, n))]),
                            np.zeros((n, model.input_matrix.shape[1])))
        U = np.array([model.forces(t) for t in grid]).T
        s, response = timed(lambda: control.forced_response(system, grid, U, X0=y0), repeats)
        rows.append((work, smd, "python-control forced_response", (s, np.abs(response.outputs.T - ref).max() / peak)))
    else:
        rows.append((work, smd, "python-control: not installed", None))
    return rows


def opensees_rows():
    import elastoplastic_vs_opensees as ep

    t, a = ep.record()
    w = 2 * np.pi / ep.T_N
    k, c = ep.M * w * w, 2 * ep.ZETA * ep.M * w
    from smdcli.analysis.spectrum import response_spectrum

    elastic = response_spectrum(t, a * G, np.array([ep.T_N]), np.array([ep.ZETA])).Sd[0, 0]
    fy = 0.25 * k * elastic
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "record.csv"
        csv.write_text("".join(f"{float(ti)!r},{float(ai)!r}\n" for ti, ai in zip(t, a)))
        seconds, result, reference, _ = ep.smd_runs(ep.scenario_text(csv, fy, 0.0))
    peak = np.abs(reference).max()
    smd = (seconds, np.abs(result.displacement[:, 0] - reference).max() / peak)
    work = f"elastoplastic 1-DOF, {len(t)}-sample record"
    found = ep.opensees(t, a, k, c, fy, 0.0)
    if found is None:
        return [(work, smd, "OpenSees: not installed", None)]
    substeps, s, x = found[-1]
    return [(work, smd, f"OpenSees ElasticPP, Newmark dt {0.01 / substeps:g}", (s, np.abs(x - reference).max() / peak))]


from chain_vs_opensees import CHAIN_MODEL  # noqa: E402  the chain's OpenSees model, one place

CHAIN_OPENSEES = """
import json, statistics, sys, time
import numpy as np
import openseespy.opensees as ops
n, dt, steps, repeats = json.loads(sys.stdin.read())
def run():
    ops.wipe()
""" + textwrap.indent(CHAIN_MODEL, "    ") + """    ops.constraints("Plain"); ops.numberer("RCM"); ops.system("BandGeneral")
    ops.algorithm("Linear"); ops.integrator("Newmark", 0.5, 0.25); ops.analysis("Transient")
    x = [0.0]
    for _ in range(steps):
        ops.analyze(1, dt)
        x.append(ops.nodeDisp(1, 1))
    return x
times = []
for _ in range(repeats):
    start = time.perf_counter(); x = run(); times.append(time.perf_counter() - start)
print(json.dumps({"seconds": statistics.median(times), "x": x}))
"""


def dense_chain_reference(model, grid) -> np.ndarray:
    """The chain's first mass, x(t) on the grid, independently of smd's modal path: the whole state with the sine
    force's generator (10 sin 5t = 10 w_0, w' = S w), stepped by one scipy expm of the dense augmented matrix."""
    from scipy.linalg import expm

    n = model.n
    A = np.zeros((2 * n + 2, 2 * n + 2))
    A[:n, n:2 * n] = np.eye(n)
    A[n:2 * n, :n] = -np.linalg.solve(model.M, model.K)
    A[n:2 * n, n:2 * n] = -np.linalg.solve(model.M, model.C)
    A[n:2 * n, 2 * n] = np.linalg.solve(model.M, model.B[:, 0]) * 10.0
    A[2 * n:, 2 * n:] = [[0.0, 5.0], [-5.0, 0.0]]
    step = expm(A * (grid[1] - grid[0]))
    z = np.zeros(2 * n + 2)
    z[2 * n + 1] = 1.0  # w = (sin 0, cos 0)
    x = np.empty(len(grid))
    for k in range(len(grid)):
        x[k] = z[0]
        z = step @ z
    return x


def opensees_chain(n: int, dt: float, steps: int, repeats: int):
    """(median seconds, first mass's x on the grid) of OpenSees on the chain, or None where it does not run."""
    import json
    import subprocess

    from elastoplastic_vs_opensees import opensees_env

    env = opensees_env()
    if env is None:
        return None
    done = subprocess.run([sys.executable, "-c", CHAIN_OPENSEES], capture_output=True, text=True, env=env,
                          input=json.dumps([n, dt, steps, repeats]))
    if done.returncode != 0:
        return None
    found = json.loads(done.stdout.strip().splitlines()[-1])
    return found["seconds"], np.array(found["x"])


def chain_rows(repeats):
    """Linear chains of 1,000 and 10,000 masses (1 kg, 100 N/m and 0.5 N s/m on every link), a sine force on the
    first, 0..10 s on 1,001 points: smd (the model built, and solved by `auto`: exact in modal coordinates at 1,000
    masses, the Taylor series on the sparse rows at 10,000) against OpenSees (the model built, Newmark average acceleration,
    banded solver, the output step); and the whole `smd simulate` of the 10,000 (scenario read, solved, element
    forces and energy balance, the HDF5 file and three PNGs written). Error: the first mass's displacement
    against the dense state transition of the 1,000-mass chain, over its peak. The 10,000-mass chain's first mass
    moves as the 1,000's to rounding over these 10 s: a wave travels at most sqrt(k/m) = 10 links a second, so the
    far end's reflection would return after 200 s."""
    import tempfile

    import wall

    from smdcli import scenario
    from smdcli.model import build, time_grid
    from smdcli.solvers import solve
    from smdcli.solvers.base import Tolerances

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        reference = peak = None
        for n in (1000, 10000):
            path = Path(tmp) / f"chain{n}.toml"
            path.write_text(wall.chain(n, False, "every"))
            sc = scenario.load(path)
            grid = time_grid(sc.time)
            if reference is None:
                reference = dense_chain_reference(build(sc), grid)
                peak = np.abs(reference).max()
            # the model built afresh each time, its modes included, as OpenSees builds its own
            seconds, result = timed(lambda: solve(build(sc), grid, "auto", Tolerances()), max(1, repeats // 3))
            smd = (seconds, np.abs(result.displacement[:, 0] - reference).max() / peak)
            work = f"linear chain of {n} masses, {len(grid)} points ({result.stats.method})"
            found = opensees_chain(n, float(grid[1] - grid[0]), len(grid) - 1, 3 if n < 10000 else 1)
            if found is None:
                rows.append((work, smd, "OpenSees: not installed or did not run", None))
                continue
            ops = (found[0], np.abs(found[1] - reference).max() / peak)
            rows.append((work, smd, "OpenSees Newmark, dt = output step", ops))
            if n == 10000:
                rows.append(simulate_row(path, Path(tmp) / "out", reference, peak, ops))
    return rows


# Times a command and reads its peak memory from a small process of its own: a child's ru_maxrss counts the
# memory of the process it was started from (Linux takes the old image's peak at exec), and this one holds GBs.
MEASURER = ("import os, subprocess, sys, time\n"
            "start = time.perf_counter()\n"
            "child = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n"
            "_, status, usage = os.wait4(child.pid, 0)\n"
            "print(time.perf_counter() - start, usage.ru_maxrss / 1024, os.waitstatus_to_exitcode(status))\n")


def simulate_row(path: Path, out: Path, reference, peak, ops):
    """The whole `smd simulate` of a scene, timed and its peak memory measured; its error read from its file."""
    import subprocess

    import h5py

    measured = subprocess.run([sys.executable, "-c", MEASURER, sys.executable, "-m", "smdcli", "simulate", str(path),
                               "-o", str(out)], capture_output=True, text=True, check=True).stdout.split()
    seconds, megabytes, code = float(measured[0]), float(measured[1]), int(measured[2])
    work = f"smd simulate {path.name} (file, plots; {megabytes:.0f} MB peak)"
    if code != 0:
        return (work, (seconds, math.nan), "smd simulate failed", None)
    with h5py.File(out / f"{path.stem}.h5") as f:
        x = f["displacement"][:, 0]
    return (work, (seconds, np.abs(x - reference).max() / peak), "OpenSees Newmark, dt = output step", ops)


def user_rhs(name: str, n: int):
    """The right-hand side and Jacobian a scipy user writes for a scene, in numpy: (f, jac)."""
    from scipy import sparse

    if name == "stiff":  # the book's M u'' + C |u'| u' + K u = 0, M = 1, C = 1001, K = 1000
        def f(t, y):
            return [y[1], -1000.0 * y[0] - 1001.0 * abs(y[1]) * y[1]]

        def jac(t, y):
            return [[0.0, 1.0], [-1000.0, -2002.0 * abs(y[1])]]

        return f, jac
    # compiled_vs_solve_ivp.chain: 1 kg masses, 100 N/m links, the first to ground also k3 = 1000 N/m^3 and
    # 0.5 N s/m, a force 10 sin 5t on it
    stiffness = sparse.diags([np.r_[200.0 * np.ones(n - 1), 100.0], -100.0 * np.ones(n - 1), -100.0 * np.ones(n - 1)],
                             [0, 1, -1], format="csr")
    base = sparse.bmat([[None, sparse.eye(n)], [-stiffness, None]], format="lil")
    base[n, n] = -0.5

    def f(t, y):
        x, v = y[:n], y[n:]
        a = -(stiffness @ x)
        a[0] += 10.0 * np.sin(5.0 * t) - 1000.0 * x[0] ** 3 - 0.5 * v[0]
        return np.concatenate([v, a])

    def jac(t, y):
        J = base.copy()
        J[n, 0] = -200.0 - 3000.0 * y[0] ** 2 if n > 1 else -100.0 - 3000.0 * y[0] ** 2
        return J.tocsc()

    return f, jac


SCIPY_RTOLS = [10 ** (-k / 2) for k in range(6, 27)]


def scipy_at_error(f, jac, span, y0, grid, reference, peak, target, method, repeats, patience):
    """scipy's method at the loosest rtol whose error is within target: (rtol, median seconds, error), or
    (None, seconds of the last run, its error) where no rtol reached it within `patience` seconds a run."""
    import time

    from scipy.integrate import solve_ivp

    n = reference.shape[1]

    def run(rtol):
        extra = {"jac": jac} if method == "Radau" else {}
        return solve_ivp(f, span, y0, method=method, t_eval=grid, rtol=rtol, atol=1e-3 * rtol * peak, **extra)

    for rtol in SCIPY_RTOLS:
        start = time.perf_counter()
        sol = run(rtol)
        seconds = time.perf_counter() - start
        error = np.abs(sol.y[:n].T - reference).max() / peak if sol.success else math.inf
        if error <= target:
            seconds, sol = timed(lambda: run(rtol), repeats if seconds < 1 else 1)
            return rtol, seconds, np.abs(sol.y[:n].T - reference).max() / peak
        if seconds > patience:
            return None, seconds, error
    return None, seconds, error


def nonlinear_rows(repeats):
    """The book's stiff damper and nonlinear chains: smd's auto against scipy's three methods at smd's error."""
    from compiled_vs_solve_ivp import chain
    from scipy.integrate import solve_ivp

    from smdcli import scenario
    from smdcli.model import build, time_grid
    from smdcli.solvers.run import solve_scenario

    scenes = [("book's stiff damper c|v|v, 1 DOF", "stiff", 1,
               scenario.load(ROOT / "scenarios" / "one_dof_nonlinear_stiff.toml"))]
    scenes += [(f"nonlinear chain of {n} masses", "chain", n, scenario.parse(chain(n), f"chain{n}.toml"))
               for n in (10, 100, 1000)]
    rows = []
    for work, name, n, sc in scenes:
        model, grid = build(sc), time_grid(sc.time)
        f, jac = user_rhs(name, n)
        y0, span = np.concatenate([model.x0, model.v0]), (grid[0], grid[-1])
        reference = solve_ivp(f, span, y0, method="DOP853", t_eval=grid, rtol=1e-13, atol=1e-16).y[:n].T
        peak = np.abs(reference).max()
        result = solve_scenario(sc, model, grid)  # kernels loaded
        target = np.abs(result.displacement - reference).max() / peak

        def peers():
            found, best = [], math.inf
            for method in ("DOP853", "RK45", "Radau"):
                patience = min(30.0, 60 * best)
                rtol, p_seconds, p_error = scipy_at_error(f, jac, span, y0, grid, reference, peak, target, method,
                                                          max(1, repeats // 2), patience)
                if rtol is None:
                    found.append((f"scipy {method}: {p_error:.1e} after {p_seconds:.1f} s, stopped", None))
                    continue
                best = min(best, p_seconds)
                found.append((f"scipy {method}, rtol {rtol:.1e}", (p_seconds, p_error)))
            return found

        seconds, result, found = timed_around(lambda: solve_scenario(sc, model, grid), repeats * 3, peers)
        smd = (seconds, target)
        work = f"{work}, {len(grid)} points ({result.stats.method})"
        rows += [(work, smd, peer, p_result) for peer, p_result in found]
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--only", choices=("spectrum", "linear", "chain", "elastoplastic", "nonlinear"),
                        help="one part of the table")
    args = parser.parse_args()
    parts = {"spectrum": lambda: spectrum_rows(args.repeats), "linear": lambda: linear_rows(args.repeats),
             "chain": lambda: chain_rows(args.repeats), "elastoplastic": opensees_rows,
             "nonlinear": lambda: nonlinear_rows(args.repeats)}
    from smdcli.solvers.integrators.compiled import KERNEL_FAMILIES, warm

    warm(*KERNEL_FAMILIES)  # compiled (or loaded) before any clock starts: an edit to a kernel clears the cache
    rows = [row for part, rows_of in parts.items() if args.only in (None, part) for row in rows_of()]
    wide = max(len(work) for work, *_ in rows)
    print(f"{'work':<{wide}} {'smd time':>10} {'smd error':>10}   {'peer':<38} {'peer time':>10} {'peer error':>10} "
          f"{'time ratio':>10}")
    for work, (s_time, s_err), peer, found in rows:
        if found is None:
            print(f"{work:<{wide}} {s_time * 1e3:8.1f} ms {s_err:10.1e}   {peer:<38}")
            continue
        p_time, p_err = found
        print(f"{work:<{wide}} {s_time * 1e3:8.1f} ms {s_err:10.1e}   {peer:<38} {p_time * 1e3:8.1f} ms "
              f"{p_err:10.1e} {p_time / s_time:9.2f}x")
    print("time ratio: peer time / smd time (above 1: smd is faster)")


if __name__ == "__main__":
    main()
