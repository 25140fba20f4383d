"""A run against time (forces, displacement, velocity, acceleration) and phase portraits.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import MAX_DRAWN, _figure, _wrap, drawn_dofs, envelope, legend_beside
from smdcli.plots.sweep import _STYLES
from smdcli.result import Result, moving_columns


def _band(t: np.ndarray, y: np.ndarray, max_points: int = MAX_DRAWN):
    """For a series that oscillates faster than the axes can draw (a 120 rad/s force over 120 s): per-bucket
    (times, low, high, mean), so the plot shows the band it fills and the motion it rides on; None otherwise."""
    n = len(t)
    buckets = max_points // 2
    if n <= max_points or _turns(y) < 2 * buckets:  # fewer than one oscillation per bucket: a line shows it
        return None
    edges = np.linspace(0, n, buckets + 1).astype(int)
    low = np.minimum.reduceat(y, edges[:-1])
    high = np.maximum.reduceat(y, edges[:-1])
    # The running mean over a bucket, twice (a triangular window two buckets wide): a plain bucket mean of an
    # oscillation that does not fit a bucket a whole number of times aliases into wiggles not in the motion.
    width = max(1, n // buckets)
    mean = _running_mean(_running_mean(y, width), width)
    centres = np.minimum((edges[:-1] + edges[1:]) // 2, n - 1)
    return t[edges[:-1]], low, high, mean[centres]


DENSE_TURNS = 200  # an orbit turning more often than this is drawn thin and see-through


def _visible_turns(x: np.ndarray) -> int:
    """How often a curve turns back by more than 2 % of its range: the turns that draw ink (a ripple does not)."""
    dx = np.diff(x)
    turning = np.flatnonzero(np.sign(dx[1:]) * np.sign(dx[:-1]) < 0) + 1
    swings = np.abs(np.diff(x[turning]))
    return int(np.count_nonzero(swings > 0.02 * (x.max() - x.min()))) if len(x) else 0


def _turns(y: np.ndarray) -> int:
    """How often a series changes direction (twice a period for an oscillation); the most over its columns."""
    dy = np.diff(y, axis=0)
    return int(np.max(np.count_nonzero(np.sign(dy[1:]) * np.sign(dy[:-1]) < 0, axis=0)))


def _running_mean(y: np.ndarray, width: int) -> np.ndarray:
    """Mean of y over a centred window of `width` samples (shorter at the ends)."""
    total = np.concatenate([[0.0], np.cumsum(y)])
    lo = np.clip(np.arange(len(y)) - width // 2, 0, len(y))
    hi = np.clip(lo + width, 0, len(y))
    return (total[hi] - total[lo]) / (hi - lo)


def _fast_window(result: Result) -> tuple[float, float] | None:
    """A window of about five periods of the fastest oscillation at the end of the run, if one is too fast to see."""
    t = result.time
    if len(t) <= MAX_DRAWN:
        return None
    turns = max(_turns(result.displacement), _turns(result.acceleration))
    if turns < MAX_DRAWN // 2:
        return None
    width = min(10 * (t[-1] - t[0]) / turns, (t[-1] - t[0]) / 10)  # two turns a period: five periods
    return t[-1] - width, t[-1]


FORCE_STYLES = ("-", "--", ":", "-.")


def response_figure(result: Result, title: str):
    """Applied forces, then displacement, velocity and acceleration against time, one colour per DOF.

    An oscillation too fast to draw over the whole run is shown as a faint band (its range) with its running
    mean, and a zoomed inset shows its last few periods."""
    ground = result.ground
    forced = ground is None and np.any(result.force != 0)
    rows = (("force", "Force F [N]"),) if forced else ()
    if ground is None:
        rows += (("displacement", "Displacement x [m]"), ("velocity", "Velocity v [m/s]"),
                 ("acceleration", "Acceleration a [m/s²]"))
    else:  # what an engineer reads: the support's motion, drift (relative motion), and what accelerometers feel
        unit = {"displacement": "m", "velocity": "m/s", "acceleration": "m/s²"}[ground.given]
        middle = ((("absolute_displacement", "Absolute x [m]"), ("displacement", "x relative to ground [m]"))
                  if ground.given == "displacement" else  # a road or a shake table: where the masses go
                  (("displacement", "x relative to ground [m]"), ("velocity", "v relative to ground [m/s]")))
        rows = (("ground", f"Ground {ground.given} [{unit}]"),) + middle + (("absolute_acceleration",
                                                                               "Absolute a [m/s²]"),)
    heights = [0.55 if name == "force" else 1.0 for name, _ in rows]
    fig = _figure(figsize=(9, 2.6 * sum(heights) + 1.2))
    axes = fig.subplots(len(rows), 1, sharex=True, gridspec_kw={"height_ratios": heights})
    fig.subplots_adjust(left=0.1, right=0.97, top=0.9, bottom=0.07, hspace=0.12)
    window = _fast_window(result)
    drawn, note = drawn_dofs(len(result.dofs), _moving(result))
    colours = {j: f"C{i % 10}" for i, j in enumerate(drawn)}  # a force drawn in its DOF's colour
    shaded = {}
    for ax, (name, label) in zip(axes, rows):
        if name == "ground":
            _draw(ax, result.time, getattr(ground, ground.given), "k", "ground")
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.4)
            shaded[name] = None
            continue
        data = result.absolute(name[len("absolute_"):]) if name.startswith("absolute_") else getattr(result, name)
        shaded[name] = None
        for j in (np.flatnonzero(np.any(data != 0, axis=0)) if name == "force" else drawn):
            dof = result.dofs[j]
            if name == "force" and not np.any(data[:, j] != 0):
                continue
            style = FORCE_STYLES[len(ax.get_lines()) % len(FORCE_STYLES)] if name == "force" else "-"
            if _draw(ax, result.time, data[:, j], colours.get(j, "k"), f"F on {dof}" if name == "force" else dof,
                     style):
                shaded[name] = shaded[name] or colours.get(j, "k")  # the first shaded series' colour, for the legend's swatch
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.4)
        if window is not None and name.endswith("acceleration"):
            _zoom_inset(ax, result, data, window, drawn)
    legends = []
    if forced:
        legends.append(_legend(axes[0], shaded["force"]))
    dof_axes = 1 if forced or ground is not None else 0
    legends.append(_legend(axes[dof_axes], shaded[rows[dof_axes][0]]))  # the DOFs' legend once
    for ax, (name, _) in zip(axes, rows):  # every other shaded panel says what its shading is, beside it
        if shaded.get(name) and ax is not axes[dof_axes] and not (forced and ax is axes[0]):
            legends.append(_legend(ax, shaded[name], lines=False))
    _beside(fig, legends)
    if not (np.any(result.displacement) or np.any(result.velocity) or np.any(result.force)) and ground is None:
        axes[0].text(0.5, 0.5, "at rest for the whole run: zero initial conditions and no force\n(a [sweep] table's "
                     "initial conditions run with smd sweep)", transform=axes[0].transAxes, ha="center",
                     va="center", fontsize=9, bbox={"facecolor": "white", "edgecolor": "0.6"})
    axes[-1].set_xlabel("Time t [s]")
    axes[0].set_xlim(result.time[0], result.time[-1])
    fig.suptitle(title + note, fontsize=11 if not note else 9)
    return fig


def _draw(ax, t: np.ndarray, y: np.ndarray, color, label: str, style: str = "-") -> bool:
    """One series: its line, or for an oscillation too fast to draw, its range shaded and its running mean.
    True when shaded."""
    band = _band(t, y)
    # the ripple: a bucket's range less what its running mean moves across it (a slow swing fills a bucket too)
    ripple = None if band is None else band[2] - band[1] - np.abs(np.gradient(band[3]))
    if ripple is not None and np.max(ripple) < 0.01 * max(float(np.ptp(y)), 1e-300):
        ax.plot(band[0], band[3], ls=style, lw=1.1, color=color, label=label)  # a ripple thinner than the line
        return False
    if band is None:
        ax.plot(*envelope(t, y), ls=style, lw=1.1, color=color, label=label)
        return False
    ax.fill_between(band[0], band[1], band[2], color=color, alpha=0.22, lw=0)
    ax.plot(band[0], band[3], ls=style, lw=1.1, color=color, label=label)
    return True


def _legend(ax, banded: str | None, lines: bool = True):
    """The axes' legend beside it (inside, it hid the lines: the F3 step at the top of the force panel), with what
    the shading means only where this panel's series was shaded (`banded`: its colour); `lines` off: that alone."""
    handles, labels = ax.get_legend_handles_labels() if lines else ([], [])
    if banded:
        from matplotlib.patches import Patch

        handles.append(Patch(color=banded, alpha=0.22, lw=0))  # as _draw shades
        labels.append("shaded: range of an\noscillation too fast\nto draw (line: its\nrunning mean)")
    return ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)


def _beside(fig, legends) -> None:
    """The axes narrowed so that the widest legend beside them ends inside the figure."""
    renderer = fig.canvas.get_renderer()
    widest = max((legend.get_window_extent(renderer).width / fig.bbox.width for legend in legends), default=0.0)
    fig.subplots_adjust(right=min(0.97, 0.98 - widest - 0.01))


def _zoom_inset(ax, result: Result, data: np.ndarray, window: tuple[float, float], drawn: np.ndarray) -> None:
    """The last few periods of the fastest oscillation, drawn in full, in an inset of `ax`."""
    low, high = ax.get_ylim()  # the data moved into the lower 54 %: the inset above them hides none
    ax.set_ylim(low, low + (high - low) / 0.54)
    inset = ax.inset_axes((0.56, 0.56, 0.42, 0.4))
    keep = (result.time >= window[0]) & (result.time <= window[1])
    for i, j in enumerate(drawn):
        inset.plot(result.time[keep], data[keep, j], lw=0.9, color=f"C{i % 10}")
    from matplotlib.ticker import MaxNLocator

    inset.set_xlim(*window)
    inset.tick_params(labelsize=7)
    inset.xaxis.set_major_locator(MaxNLocator(3, prune="upper"))  # a label at the right edge ran past it
    inset.ticklabel_format(axis="x", useOffset=False)
    inset.yaxis.set_major_locator(MaxNLocator(3))
    inset.text(0.02, 0.96, f"zoom on the last {window[1] - window[0]:.3g} s, every sample", transform=inset.transAxes,
               fontsize=7, va="top", bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1})
    inset.grid(True, alpha=0.3)
    inset.set_facecolor("white")


def _moving(result: Result) -> np.ndarray | None:
    """The DOFs that move in the run, where most of many do not (result.moving_columns)."""
    return moving_columns(result.displacement, result.velocity, result.acceleration)


def phase_figure(result: Result, title: str):
    """Phase portrait of a run: velocity against displacement per DOF, start and direction marked."""
    drawn, note = drawn_dofs(len(result.dofs), _moving(result))
    _, x, v = result.with_events()  # a stick's corner, an impact's jump: the samples alone cut them
    curves = [(result.dofs[j], x[:, j], v[:, j]) for j in drawn]
    return portrait_figure(curves, f"{title}\nphase portrait{note}")


def portrait_figure(curves, title: str, poincare=None):
    """Phase portraits: velocity against displacement per curve (label, x, v), start marked, direction arrowed;
    Poincare points (label, x, v) drawn as dots."""
    fig = _figure(figsize=(7.5, 6.5))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.13, right=0.72, top=0.88, bottom=0.1)
    for i, (label, x, v) in enumerate(curves):
        color = f"C{i % 10}"
        # Behind Poincare points, or an orbit of hundreds of turns (a fast forced mass): thin and see-through, so
        # that its shape shows instead of a solid blob.
        faint = poincare is not None or max(_visible_turns(np.asarray(x)), _visible_turns(np.asarray(v))) > DENSE_TURNS
        ax.plot(x, v, _STYLES[i % len(_STYLES)] if len(curves) <= 4 and not faint else "-", lw=0.4 if faint else 1.3,
                color=color, alpha=0.35 if faint else 1.0, label=_wrap(label, 26))
        ax.plot(x[0], v[0], "o", color=color, ms=7, mfc="white", mew=1.5)
        _direction_arrows(ax, x, v, color)
    if poincare is not None:
        for i, (label, x, v) in enumerate(poincare):
            ax.plot(x, v, "o", color=f"C{i % 10}", ms=6, mec="k", mew=0.6, zorder=5,
                    label=_wrap(f"{label}: once per period", 26))
    return _portrait_frame(fig, ax, title, "Displacement x [m]", "Velocity v [m/s]")


def _portrait_frame(fig, ax, title: str, xlabel: str, ylabel: str):
    """A portrait's legend (with the start marker's entry) beside it, its axis labels, grid and title."""
    from matplotlib.ticker import MaxNLocator

    ax.plot([], [], "o", color="k", mfc="white", label="start")
    ax.xaxis.set_major_locator(MaxNLocator(nbins=6))  # labels like -0.075 ran into each other at the default
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.4)
    ax.set_title(_wrap(title, 80), fontsize=10)
    legend_beside(fig, ax, fontsize=8, frameon=False)
    return fig


def hysteresis_figure(loops, title: str):
    """Hysteresis loops: each spring's force against its deformation (label, d, T), start marked, direction
    arrowed."""
    fig = _figure(figsize=(7.5, 6.5))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.13, right=0.72, top=0.88, bottom=0.1)
    for i, (label, d, force) in enumerate(loops):
        color = f"C{i % 10}"
        ax.plot(d, force, "-", lw=1.1, color=color, label=_wrap(label, 26))
        ax.plot(d[0], force[0], "o", color=color, ms=7, mfc="white", mew=1.5)
        _direction_arrows(ax, d, force, color)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    return _portrait_frame(fig, ax, title, "Deformation d = x_b - x_a [m]", "Spring force (tension) [N]")


def _direction_arrows(ax, x: np.ndarray, v: np.ndarray, color, count: int = 4) -> None:
    """Arrowheads along a trajectory, spaced by arc length in the plot's own scale, showing the direction of motion."""
    if len(x) < 3:
        return
    sx, sv = np.ptp(x) or 1.0, np.ptp(v) or 1.0
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x) / sx, np.diff(v) / sv))])
    if arc[-1] == 0:
        return
    # Early along the path, where the motion is largest and the arrows are clear of the end point.
    for target in arc[-1] * np.array([0.04, 0.12, 0.25, 0.45][:count]):
        i = min(int(np.searchsorted(arc, target)), len(x) - 2)
        ax.annotate("", xy=(x[i + 1], v[i + 1]), xytext=(x[i], v[i]),
                    arrowprops={"arrowstyle": "-|>", "color": color, "lw": 1.2, "mutation_scale": 14})
