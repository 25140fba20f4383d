"""The `smd` command: parse, call the library, print, choose the exit code.

The top layer: imports the commands lazily, inside each command, so that `smd --help` imports
none of numpy, scipy, matplotlib or h5py. Must not import: scipy, matplotlib, h5py at module level.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional

import typer

from smdcli import __version__, interrupts
from smdcli.cli_analyses import fit, fragility, ida, optimize, psd, record, rsa, sensitivity, spectrum
from smdcli.cli_files import diff_files, export
from smdcli.cli_support import _carried_out, _fail, _interrupted, _message, _print_json, _report, plain_coercion, plain_help
from smdcli.progress import wanted as progress_wanted
from smdcli.solvers.registry import NAMES as METHOD_NAMES, names as method_names

OVERRIDE_HELP = f"Solver, overriding the scenario's solver.method: {', '.join(METHOD_NAMES)}."
from smdcli.text import plural

plain_help()
plain_coercion()


def _typer() -> typer.Typer:
    """An smd command group (its settings in one place: the whole app, and the one-command app run parses with)."""
    return typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                       help="Simulate spring-mass-damper systems from TOML scenarios: exact where linear, measured "
                            "where not.")


app = _typer()


def _version(value: bool):
    if value:
        typer.echo(f"smd {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit.")):
    """smd: spring-mass-damper simulation."""


@app.command()
def simulate(
    scenarios: List[Path] = typer.Argument(..., help="Scenario TOML files."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    method: Optional[str] = typer.Option(None, "--method", help=OVERRIDE_HELP),
    rtol: Optional[float] = typer.Option(None, "--rtol", help="Relative tolerance override (> 0)."),
    atol: Optional[float] = typer.Option(None, "--atol", help="Absolute tolerance override (> 0)."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json",
                                 help="Print the summaries as JSON: one entry per file, failed ones too."),
    fail_fast: bool = typer.Option(False, "--fail-fast", help="Stop at the first scenario that fails."),
    save_partial: bool = typer.Option(False, "--save-partial", help="When a solver fails, write what it computed "
                                      "to OUT/<stem>_partial.h5, marked failed."),
    junit: Optional[Path] = typer.Option(None, "--junit", help="Write the scenarios' \\[\\[expect]] checks as a JUnit "
                                         "XML report, a test case per check."),
    strict: bool = typer.Option(False, "--strict", help="Exit 1 where a run is suspect: a dissipated energy "
                                "that decreases, a law's rule broken, an energy balance beyond its stated accuracy."),
):
    """Solve each scenario; write OUT/<stem>.h5 and OUT/<stem>_response.png, _phase.png, _energy.png."""
    from smdcli.commands.simulate import Options, failed_summary, format_summary
    from smdcli.commands.simulate import simulate as run_one
    from smdcli.commands.simulate import summary
    from smdcli.errors import SmdError
    from smdcli.progress import bar

    from smdcli.solvers.run import check_overrides

    try:  # once, before any scenario: the same check as smdcli.simulate()'s
        check_overrides(method, rtol, atol)
    except SmdError as exc:
        code = _report(exc)
        if as_json:  # a script still gets its entry per file
            _print_json([failed_summary(path, _message(exc), code) for path in scenarios])
        raise typer.Exit(code)
    options = Options(method=method, rtol=rtol, atol=atol, plots=not no_plots, save_partial=save_partial,
                      strict=strict)
    worst = 0
    summaries, suites = [], []
    with bar("simulating", len(scenarios), len(scenarios) > 1 and progress_wanted(quiet, as_json),
             transient=True) as advance:
        for index, path in enumerate(scenarios):
            advance(0, Path(path).name)  # the file's name: a whole path collapses the bar at 80 columns
            try:
                run = run_one(path, out, options)
            except (SmdError, OSError) as exc:
                code = _report(exc)
                worst = max(worst, code)
                summaries.append(failed_summary(path, _message(exc), code))
                suites.append((str(path), 0.0, (), _message(exc)))
                advance(1)
                if fail_fast:
                    summaries += [failed_summary(p, None, None) for p in scenarios[index + 1:]]
                    break
                continue
            except KeyboardInterrupt as exc:
                raise _interrupted(exc)
            data = summary(run)
            summaries.append(data)
            worst = max(worst, data["exit_code"])
            suites.append((str(path), run.result.stats.wall_time_s, run.checks, None))
            if not quiet and not as_json:
                advance.above(format_summary(data))
            advance(1)
    if junit is not None:
        from smdcli.commands.expect import write_junit

        try:
            write_junit(junit, suites)
        except OSError as exc:
            worst = max(worst, _report(exc))
    if as_json:
        _print_json(summaries)
    raise typer.Exit(worst)


@app.command()
def info(
    scenario: Path = typer.Argument(..., help="Scenario TOML file."),
    as_json: bool = typer.Option(False, "--json", help="Print as JSON."),
    state_space: Optional[Path] = typer.Option(None, "--state-space", help="Also write A, B, C, D (states x, v; "
                                               "inputs the DOFs' forces; outputs x) to FILE.npz or FILE.mat."),
):
    """DOFs, M C K, natural frequencies, damping ratios and regimes, stiffness, what auto would pick."""
    from smdcli.commands.simulate import format_info
    from smdcli.commands.simulate import info as describe

    _carried_out(lambda: describe(scenario, state_space), {"scenario": str(scenario)}, as_json, False,
                 lambda data: data, lambda _, data: format_info(data))


@app.command("compare-solvers")
def compare_solvers(
    scenario: Path = typer.Argument(..., help="Scenario TOML file."),
    methods: Optional[str] = typer.Option(None, "--methods", help="Comma list; default: "
                                         f"{', '.join(method_names(compare='adaptive') + method_names(compare='fixed'))}."),
    tolerances: Optional[str] = typer.Option(None, "--tolerances",
                                             help="Comma list of rtol or rtol/atol; default 1e-3..1e-10, atol = rtol/1000."),
    steps: Optional[str] = typer.Option(None, "--steps", help="Comma list of fixed steps in s; default h*omega_max 3..0.02."),
    repeats: int = typer.Option(3, "--repeats", help="Timings per run; the median is kept (runs over 0.2 s: once)."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_breakpoints: bool = typer.Option(False, "--no-breakpoints",
                                        help="Do not restart adaptive methods at force discontinuities (for study)."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the runs as JSON."),
):
    """Run methods over ladders of tolerances and steps against a reference; chart error against cost."""
    from smdcli.commands.compare import as_dict, format_table, run_and_write

    _carried_out(lambda: run_and_write(scenario, out, methods, tolerances, steps, repeats,
                                       breakpoints=not no_breakpoints, plots=not no_plots,
                                       progress=progress_wanted(quiet, as_json)),
                 {"scenario": str(scenario)}, as_json, quiet, lambda done: as_dict(done[0]),
                 lambda done, _: format_table(done[0]) + "\nwrote " + ", ".join(str(p) for p in done[1]))


@app.command()
def sweep(
    scenario: Path = typer.Argument(..., help="Scenario TOML file (its sweep table is the default family)."),
    param: Optional[List[str]] = typer.Option(None, "--param", help="Field path to sweep (damper[0].c, mass.m1.m, "
                                              "force[0].omega, time.end, zeta); twice for a grid."),
    values: Optional[List[str]] = typer.Option(None, "--values", help="Values per --param: a,b,c | start:stop:step | "
                                               "linspace(a,b,n) | logspace(a,b,n)."),
    labels: Optional[str] = typer.Option(None, "--labels", help="Comma list of legend labels, one per member."),
    ic: Optional[List[str]] = typer.Option(None, "--ic", help="An initial condition: x0=0.1,v0=1 (or m1.x0=..); repeat."),
    frequency: Optional[str] = typer.Option(None, "--frequency", help="Frequency response over SPEC rad/s "
                                            "(append Hz for hertz), e.g. 0:10:0.2 or 'linspace(0.1,2,200) Hz'."),
    normalized: bool = typer.Option(False, "--normalized", help="1-DOF: X K / F0 and theta against omega / omega_n."),
    input_dof: Optional[str] = typer.Option(None, "--input", help="DOF the unit force acts on (default: first force's)."),
    direction: Optional[str] = typer.Option(None, "--direction", help="Measured response: up, down or both."),
    measure: bool = typer.Option(False, "--measure", help="Linear scene: also simulate to steady state and compare."),
    quantity: Optional[str] = typer.Option(None, "--quantity", help="Overlay plot of displacement, velocity, "
                                           "acceleration or force."),
    metric: Optional[str] = typer.Option(None, "--metric", help="peak_displacement, rms_displacement, settling_time "
                                         "or peak_ground_force."),
    method: Optional[str] = typer.Option(None, "--method", help="Solver for every member (default: the scenario's): "
                                          f"{', '.join(METHOD_NAMES)}."),
    keep: Optional[str] = typer.Option(None, "--keep", help="What the file stores per member: full (time histories "
                                       "and metrics, the default) or metrics."),
    resume: bool = typer.Option(False, "--resume", help="Finish the sweep an interrupted run left in "
                                "<stem>_sweep.partial.h5 (same command line)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Run the member chunks on the Dask "
                                            "scheduler at ADDRESS (tcp://host:8786), or 'local' for a LocalCluster "
                                            "of --workers processes (needs the \\[dask] extra)."),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, help="Processes for nonlinear members "
                                          "(default: the number of cores)."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Write the HDF5 file only."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
):
    """Run a family: parameters over grids, initial conditions, or a frequency response; one HDF5 and plots."""
    from smdcli.commands.sweep import format_summary, run_and_write, summary
    from smdcli.sweep.stream import KEEPS

    if method is not None:
        from smdcli.solvers.registry import method_problem

        problem = method_problem(method)
        if problem:
            raise typer.BadParameter(problem, param_hint="--method")
    options = {"parameter": tuple(param or ()), "values": tuple(values or ()),
               "labels": tuple(x.strip() for x in labels.split(",")) if labels else (),
               "ic": tuple(ic or ()), "frequency": frequency, "normalized": normalized or None,
               "input": input_dof, "direction": direction, "measure": measure or None, "quantity": quantity,
               "metric": metric, "method": method}
    if keep is not None and keep not in KEEPS:
        raise typer.BadParameter(f"expected one of {', '.join(KEEPS)}, found {keep!r}", param_hint="--keep")
    run = _carried_out(lambda: run_and_write(scenario, out, options, workers, plots=not no_plots,
                                             progress=progress_wanted(quiet, as_json), keep=keep, resume=resume,
                                             scheduler=scheduler),
                       {"scenario": str(scenario)}, as_json, quiet, summary, lambda _, data: format_summary(data))
    raise typer.Exit(1 if run.failed_count else 0)


app.command()(spectrum)
app.command()(record)
app.command()(psd)
app.command()(rsa)
app.command()(sensitivity)
app.command()(fit)
app.command()(optimize)
app.command()(fragility)
app.command()(ida)


@app.command()
def phase(
    scenarios: List[Path] = typer.Argument(..., help="Scenario TOML files, overlaid."),
    dof: Optional[str] = typer.Option(None, "--dof", help="Comma list of DOFs (default: all)."),
    ic: Optional[List[str]] = typer.Option(None, "--ic", help="An initial condition x0=..,v0=.. (repeat): a family."),
    poincare: bool = typer.Option(False, "--poincare", help="Also sample once per forcing period (Poincare section)."),
    periods: Optional[int] = typer.Option(None, "--periods", help="Run this many forcing periods instead of the "
                                          "scenario's time span."),
    skip_periods: int = typer.Option(0, "--skip-periods", help="Poincare: leave out the first periods (transient)."),
    hysteresis: bool = typer.Option(False, "--hysteresis", help="Plot force against deformation of every "
                                    "hysteretic spring instead (OUT/NAME_hysteresis.png and .h5)."),
    method: Optional[str] = typer.Option(None, "--method", help=OVERRIDE_HELP),
    name: Optional[str] = typer.Option(None, "--name", help="Output name: OUT/NAME_portrait.png and .h5 (default: "
                                       "the scenario's stem, or FIRST_and_K_more for several)."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
):
    """Phase portraits (x against v) of DOFs, scenarios or a family, start and direction marked; --poincare;
    --hysteresis: force against deformation of hysteretic springs."""
    from smdcli.commands.phase import portraits

    def describe(run, _) -> str:
        points = sum(len(c.x) for c in run.poincare or ())
        return (plural(len(run.curves), "hysteresis loop" if run.hysteresis else "trajectory",
                       "hysteresis loops" if run.hysteresis else "trajectories")
                + (f", {plural(points, 'Poincare point')} (T = {run.period:.4g} s)" if run.poincare else "")
                + "\nwrote " + ", ".join(str(p) for p in run.outputs))

    _carried_out(lambda: portraits(scenarios, out, dof, tuple(ic or ()), poincare, periods, skip_periods, method,
                                   progress=progress_wanted(quiet), name=name, hysteresis=hysteresis),
                 {}, False, quiet, lambda run: None, describe)


@app.command()
def draw(
    scenario: Path = typer.Argument(..., help="Scenario TOML file."),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
):
    """A schematic of the system from its elements: masses, springs, dampers (nonlinear in red), walls, forces."""
    from smdcli.commands.draw import write_schematic

    _carried_out(lambda: write_schematic(scenario, out), {}, False, quiet, lambda png: None,
                 lambda png, _: f"wrote {png}")


@app.command()
def schema():
    """Print a JSON Schema of the scenario format, for an editor's TOML extension (completion and checking)."""
    import json

    from smdcli.commands.schema import full_schema

    typer.echo(json.dumps(full_schema(), indent=2))


@app.command()
def animate(
    scenario: Path = typer.Argument(..., help="Scenario TOML file."),
    fps: int = typer.Option(20, "--fps", help="Frames per second of the GIF."),
    seconds: Optional[float] = typer.Option(None, "--seconds", help="Length of the GIF (default: the run, at most 20 s)."),
    scale: Optional[float] = typer.Option(None, "--scale", help="Displacement magnification (default: the largest "
                                          "motion drawn as 0.3 of the mass spacing)."),
    start: Optional[float] = typer.Option(None, "--start", help="First simulated time shown."),
    end: Optional[float] = typer.Option(None, "--end", help="Last simulated time shown."),
    method: Optional[str] = typer.Option(None, "--method", help=OVERRIDE_HELP),
    out: Path = typer.Option(Path("results"), "-o", "--out", help="Output folder."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print errors only."),
):
    """A GIF of the masses moving, springs and dampers drawn, with a time stamp on each frame."""
    from smdcli.commands.draw import animate as make_gif

    def describe(made, _) -> str:
        gif, facts = made
        return (f"{plural(facts['frames'], 'frame')} at {facts['fps']} fps, t = {facts['start']:g} .. "
                f"{facts['end']:g} s, displacements x {facts['scale']:.3g}, {facts['bytes'] / 2**20:.2f} MB\nwrote {gif}")

    _carried_out(lambda: make_gif(scenario, out, fps, seconds, scale, start, end, method, progress=progress_wanted(quiet)),
                 {}, False, quiet, lambda made: None, describe)


app.command("diff")(diff_files)
app.command("export")(export)


def _usage_line(exc) -> str:
    """click's usage error as one line: the command, what is wrong, where to read more."""
    context = getattr(exc, "ctx", None)
    command = context.command_path if context is not None else "smd"
    if getattr(exc, "possibilities", None):  # click compares with the dashes: --bogus came out "like" --out
        import difflib

        words = {option.lstrip("-"): option for option in exc.possibilities}
        exc.possibilities = [words[w] for w in difflib.get_close_matches(exc.option_name.lstrip("-"), list(words))]
    return f"{exc.format_message()} (see '{command} --help')"


def _app_for(args: list[str]) -> typer.Typer:
    """The app that parses ARGS: where they name a command, a group of that command alone (typer builds every
    command's parser and its options' checks before it reads one: 14 commands for one, 15 ms of every call); else
    the whole app, for the listing, a misspelt command, the version."""
    from typer.main import get_command_name

    name = args[0] if args else None
    chosen = [c for c in app.registered_commands if (c.name or get_command_name(c.callback.__name__)) == name]
    if len(chosen) != 1:
        return app
    one = _typer()
    one.registered_callback = app.registered_callback
    one.registered_commands = chosen
    return one


def run(args: list[str]) -> int:
    """Run `smd ARGS` and return its exit code: one line for a usage error, 130/143 for an interrupt."""
    import shlex

    from smdcli import provenance

    # typer >= 0.20 carries its own copy of click: take the classes from wherever typer's come from.
    exceptions = sys.modules[typer.BadParameter.__module__]
    usage_error = exceptions.UsageError
    no_args = getattr(exceptions, "NoArgsIsHelpError", ())

    provenance.set_command_line(shlex.join(["smd", *args]))
    import smdcli.cli_support as support

    support._announced = False  # each command reports its own interrupt (a notebook or a test runs several)
    import os
    import warnings

    try:
        with warnings.catch_warnings():
            if not os.environ.get("SMD_DEBUG"):
                # smd says what went wrong in its own lines; numpy's RuntimeWarnings (an overflow it then reports)
                # and libraries' notices would only bury them
                warnings.simplefilter("ignore")
            code = _app_for(args)(args=args, prog_name="smd", standalone_mode=False)
    except no_args:  # `smd` alone: the help was printed
        code = 2
    except usage_error as exc:
        _fail(_usage_line(exc))
        code = 2
    except KeyboardInterrupt as exc:
        code = _interrupted(exc).exit_code
    except BrokenPipeError:  # `smd ... | head`: the reader left; nothing more to say
        sys.stderr.close()
        code = 1
    except Exception as exc:  # a defect of smd's, not of the input: one line, unless asked for the traceback
        if interrupts.received() is not None:  # e.g. an import cut short by the signal: an interrupt, not a defect
            return _interrupted(KeyboardInterrupt()).exit_code
        if os.environ.get("SMD_DEBUG"):
            raise
        _fail(f"internal error: {type(exc).__name__}: {exc}; please report it (SMD_DEBUG=1 shows the traceback)")
        code = 1
    return code if isinstance(code, int) else 0


def main() -> None:
    """Console-script entry point."""
    # A signal that came at any point decides, even one whose exception was swallowed or that typer turned into
    # a silent exit 130; once settled, signals are only recorded, so a later one changes nothing. Settling is inside
    # the try: a signal that lands after run returns, before the handlers are switched, is caught like any other.
    try:
        interrupts.install()
        code = run(sys.argv[1:])
        signum = interrupts.settle()
    except KeyboardInterrupt:  # one outside run's own handling: in its first imports, in a handler, after it
        code, signum = 1, interrupts.settle()  # recorded all the same: the signal decides the exit code
    if signum is not None:
        import os

        code = _interrupted(KeyboardInterrupt()).exit_code
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)  # files are already cleaned up; an import the signal cut short may not survive finalization
    sys.exit(code)
