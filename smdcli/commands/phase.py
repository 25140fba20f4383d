"""smd phase: phase portraits (displacement against velocity) of runs, families and Poincare sections, and the
hysteresis loops (force against deformation) of hysteretic springs.

Must not import: cli.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from smdcli.solvers.run import load as load_checked
from smdcli.errors import UsageError
from smdcli.model import time_grid
from smdcli.progress import bar
from smdcli.scenario import Scenario, TimeSpec

POINTS_PER_PERIOD = 64  # portrait resolution when --periods sets the run's length
_NAME = re.compile(r"[A-Za-z0-9._-]{1,100}")


@dataclass
class Curve:
    """One trajectory of one DOF: its label, time, displacement and velocity."""

    label: str
    time: np.ndarray
    x: np.ndarray
    v: np.ndarray


@dataclass
class PhaseRun:
    """What one `smd phase` drew and wrote."""

    curves: list[Curve]
    poincare: list[Curve] | None = None
    period: float | None = None
    hysteresis: bool = False  # curves are (deformation, force) loops of hysteretic springs, not (x, v)
    outputs: list[Path] = field(default_factory=list)


def forcing_period(sc: Scenario) -> float:
    """The period of the scene's first periodic force (a sine, a square wave, a Fourier series)."""
    from smdcli.shapes import build_signal

    for force in sc.forces:
        period = build_signal(force).period
        if period is not None:
            return period
    raise UsageError(f"{sc.path}: --poincare samples once per forcing period, and this scene has no periodic force")


def _runs(sc: Scenario, ics: tuple[str, ...]) -> list[tuple[str, Scenario]]:
    """(label, scenario) of each trajectory a scenario stands for: itself, or its time-domain family."""
    table = dict(sc.sweep)
    time_family = ics or ("frequency" not in table and ("ic" in table or "parameter" in table))
    if not time_family:
        return [(sc.title or sc.stem, sc)]
    from smdcli.sweep import build_family, read_spec

    family = build_family(sc, read_spec(sc, {"ic": ics} if ics else {}))
    return [(family.labels[s], family.member_scenario(s)) for s in range(len(family))]


def _solve(sc: Scenario, method: str | None, events: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, x, v) of a run; with `events`, each located event's state merged in time order (a stop's contact point,
    a stick's corner: the samples alone cut them)."""
    from smdcli.solvers.run import solve_checked

    result = solve_checked(sc, method)
    return result.with_events() if events else (result.time, result.displacement, result.velocity)


def hysteretic_springs(sc: Scenario) -> list:
    """The springs of the scene whose law has a history (elastoplastic, bilinear, Bouc-Wen)."""
    return [e for e in sc.springs if e.nonsmooth is not None]


def _loops(sc: Scenario, method: str | None, label: str | None) -> list[Curve]:
    """Force against deformation d = x_b - x_a of every hysteretic spring (Curve.x = d, Curve.v = tension)."""
    from smdcli.model import build
    from smdcli.solvers.run import solve_checked
    from smdcli.analysis.energy import with_physics
    from smdcli.result import merged

    result = with_physics(build(sc), solve_checked(sc, method))
    forces, index = result.elements, {name: j for j, name in enumerate(sc.dof_names)}
    t_event, x_event, _, tension_event = result.nonsmooth.event_state()
    loops = []
    for spring in hysteretic_springs(sc):
        def deformation(x):
            a, b = (x[:, index[n]] if n in index else np.zeros(len(x)) for n in spring.connects)
            return b - a

        tension = forces.tension(spring.path)
        # the yield and unloading corners: each event's state, where the samples would draw a chord
        t, d, force = result.time, deformation(result.displacement), tension
        if len(t_event):
            t, d, force = merged(t, (d, force), t_event,
                                 (deformation(x_event), tension_event[:, result.nonsmooth.paths.index(spring.path)]))
        name = f"{spring.path} ({spring.law}, {' - '.join(spring.connects)})"
        loops.append(Curve(f"{label}: {name}" if label else name, t, d, force))
    return loops


def portraits(paths: list[Path], out: Path, dofs: str | None = None, ics: tuple[str, ...] = (),
              poincare: bool = False, periods: int | None = None, skip_periods: int = 0,
              method: str | None = None, plots: bool = True, progress: bool = False,
              name: str | None = None, hysteresis: bool = False) -> PhaseRun:
    """Load every scenario first (input errors before any work), solve, draw and write `<name>_portrait.*`
    (`<name>_hysteresis.*` with `hysteresis`: force against deformation of every hysteretic spring).

    The name is the scenario's stem, `<first>_and_<k>_more` for several scenarios, or `name`."""
    from smdcli.io.folders import output_folder

    scenarios = [load_checked(p) for p in paths]
    if ics and len(scenarios) > 1:
        raise UsageError("--ic: give one scenario with an initial-condition family")
    if name is not None and not _NAME.fullmatch(name):
        raise UsageError(f"--name: expected letters, digits, '.', '_' or '-' (a file name stem), found {name!r}")
    chosen = [d.strip() for d in dofs.split(",") if d.strip()] if dofs else None  # None: each scenario's own DOFs
    for sc in scenarios:
        missing = [d for d in chosen or () if d not in sc.dof_names]
        if missing:
            raise UsageError(f"--dof: {sc.path} has no DOF {missing[0]!r}; its DOFs are {', '.join(sc.dof_names)}")
    if hysteresis:
        if poincare or dofs:
            raise UsageError("--hysteresis draws springs, not DOFs: leave out --poincare and --dof")
        for sc in scenarios:
            if not hysteretic_springs(sc):
                from smdcli.elements import SPRING_LAWS

                laws = ", ".join(f'"{name}"' for name in SPRING_LAWS)
                raise UsageError(f"--hysteresis: {sc.path} has no hysteretic spring (law = {laws})")
    runs = [(label if len(scenarios) == 1 else f"{sc.stem}: {label}", member, sc)
            for sc in scenarios for label, member in _runs(sc, ics)]
    if periods is not None and periods < 1 or skip_periods < 0:
        raise UsageError("--periods must be at least 1 and --skip-periods at least 0")
    period = None
    if poincare:
        period = forcing_period(scenarios[0])
        for _, member, _ in runs:
            if abs(forcing_period(member) - period) > 1e-12 * period:
                raise UsageError(f"--poincare: {member.path} has another forcing period; overlay scenes of one period")
    out_dir = output_folder(out)
    curves, sections = [], [] if poincare else None
    with bar("phase portraits", len(runs) * (2 if poincare else 1), progress) as advance:
        alone = len(runs) == 1
        for label, member, sc in runs:
            if periods is not None:
                span = (period or forcing_period(member)) if period or member.forces else None
                if span is None:
                    raise UsageError(f"--periods: {member.path} has no periodic force to count periods of")
                spacing = np.diff(time_grid(member.time)[:2])[0]
                member = dataclasses.replace(member, time=TimeSpec(
                    member.time.start, member.time.start + periods * span, step=min(spacing, span / POINTS_PER_PERIOD)))
            if hysteresis:  # labels short enough for the legend: the stem stands for the title
                curves += _loops(member, method, None if alone else label if member is not sc else sc.stem)
                advance(1, label)
                continue
            t, x, v = _solve(member, method)
            advance(1, label)
            dofs = chosen or member.dof_names
            names = {dof: dof if alone else (label if len(dofs) == 1 else f"{label}: {dof}") for dof in dofs}
            for dof in dofs:
                j = member.dof_names.index(dof)
                curves.append(Curve(names[dof], t, x[:, j], v[:, j]))
            if poincare:
                count = int(math.floor((member.time.end - member.time.start) / period * (1 + 1e-12)))
                if count < 1:
                    raise UsageError(f"{member.path}: the run is shorter than one forcing period ({period:.4g} s); "
                                     "use --periods")
                sampled = dataclasses.replace(member, time=TimeSpec(member.time.start,
                                                                    member.time.start + count * period, step=period))
                ts, xs, vs = _solve(sampled, method, events=False)
                advance(1, f"{label}: Poincare")
                keep = slice(min(skip_periods, len(ts) - 1), None)
                for dof in dofs:
                    j = member.dof_names.index(dof)
                    sections.append(Curve(names[dof], ts[keep], xs[keep, j], vs[keep, j]))
    run = PhaseRun(curves, sections, period, hysteresis)
    kind = "hysteresis" if hysteresis else "portrait"
    stem = name or (scenarios[0].stem if len(scenarios) == 1 else f"{scenarios[0].stem}_and_{len(scenarios) - 1}_more")
    from smdcli.io.atomic import together

    with together():  # the files appear together, or none of them
        h5 = out_dir / f"{stem}_{kind}.h5"
        _write(h5, scenarios[0], run)
        run.outputs.append(h5)
        if plots:
            from smdcli.plots.common import save_figure
            from smdcli.plots.response import hysteresis_figure, portrait_figure

            title = scenarios[0].title or scenarios[0].stem if len(scenarios) == 1 else \
                " vs ".join(sc.stem for sc in scenarios)
            if hysteresis:
                figure = hysteresis_figure([(c.label, c.x, c.v) for c in curves],
                                           title + "\nhysteresis: spring force vs deformation")
            else:
                title += "\nphase plot: displacement vs velocity" + (
                    f"; Poincare section: dots once per forcing period T = {period:.4g} s"
                    + (f" after {skip_periods} periods" if skip_periods else "") if poincare else "")
                figure = portrait_figure([(c.label, c.x, c.v) for c in curves], title,
                                         [(c.label, c.x, c.v) for c in sections] if poincare else None)
            png = out_dir / f"{stem}_{kind}.png"
            save_figure(figure, png)
            run.outputs.append(png)
    return run


def _write(path: Path, sc: Scenario, run: PhaseRun) -> None:
    """One group per curve (time, displacement, velocity; time, deformation, force for loops), Poincare points
    apart."""
    import h5py

    from smdcli.io.atomic import atomic_path
    from smdcli.io.hdf5 import axis, with_scales, write_header

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        write_header(f, sc, "phase")
        for group_name, curves in (("curves", run.curves), ("poincare", run.poincare or [])):
            if not curves:
                continue
            group = f.create_group(group_name)
            if run.period and group_name == "poincare":
                group.attrs["period_s"] = run.period
            for i, c in enumerate(curves):
                g = group.create_group(f"{i:03d}")
                g.attrs["label"] = c.label
                columns = (("deformation", "m"), ("force", "N")) if run.hysteresis else \
                    (("displacement", "m"), ("velocity", "m/s"))
                time = axis(g, "time", c.time)
                time.attrs["units"] = "s"
                for (name, units), data in zip(columns, (c.x, c.v)):
                    with_scales(g.create_dataset(name, data=data), time).attrs["units"] = units
