"""The response before and at the optimum: a receptance with its peaks marked, or the time history.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure, envelope, plain_log_labels


def optimize_figure(run, before, after, surface=None):
    """before, after: (x axis, y) of the objective's response at the start and at the optimum (frequency in rad/s
    and |H|, or time and x), drawn together; the located peaks marked (a receptance's, or the largest in time).
    surface: for two parameters, (first's values, second's, objective) drawn beside as contours with the best
    search's path, its start, the optimum and the other optima."""
    fig = _figure(figsize=(14.0, 4.6) if surface is not None else (9.0, 4.2))
    ax = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.5, 1.0]})[0] if surface is not None else fig.subplots()
    receptance = run.in_frequency
    support = run.objective.startswith("peak_transmissibility")
    dof = run.objective.partition(":")[2]
    unit = "" if run.units == "1" else f" {run.units}"
    for (xs, ys), label, color in ((before, f"start ({run.value_before:.4g}{unit})", "0.55"),
                                   (after, f"optimum ({run.value:.4g}{unit})", "C0")):
        if receptance:
            ax.plot(xs, ys, color=color, lw=1.4, label=label)
        else:
            ax.plot(*envelope(xs, ys), color=color, lw=1.2, label=label)
    if receptance:
        for rows, color in ((run.peaks_before, "0.55"), (run.peaks, "C3")):
            ax.plot(rows[:, 0], rows[:, 1], "o", color=color, ms=5, mfc="none")
        ax.set_yscale("log")
        ax.set_xlabel("Frequency [rad/s]")
        ax.set_ylabel(f"|a_{dof} / a_ground| (absolute)" if support else f"|x_{dof} / F| [m/N]")
        plain_log_labels(ax.yaxis)
    else:  # the largest peaks in time, those within 1e-6 of the largest (the active ones) marked on their curve
        for rows, (xs, ys), color in ((run.peaks_before, before, "0.55"), (run.peaks, after, "C3")):
            active = rows[rows[:, 1] >= (1 - 1e-6) * rows[:, 1].max(initial=0.0)] if len(rows) else rows
            ax.plot(active[:, 0], np.sign(np.interp(active[:, 0], xs, ys)) * active[:, 1], "o", color=color, ms=6,
                    mfc="none")
        ax.set_xlabel("Time [s]")
        kind = run.objective.partition(":")[0]
        ax.set_ylabel({"peak_acceleration": f"a_{dof} (absolute) [m/s^2]", "peak_drift": f"x_{dof.replace('-', ' - x_')} [m]",
                       "dissipated": f"energy dissipated by {dof} [J]"}.get(kind, f"x_{dof} [m]"))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    values = ", ".join(f"{p} = {v:.4g}" for p, v in zip(run.parameter, run.optimum))
    fig.suptitle(f"minimize {run.objective}: {values}", fontsize=10)
    if surface is None:
        fig.subplots_adjust(left=0.1, right=0.97, bottom=0.13, top=0.9)
        return fig
    _contours(fig.axes[1], run, *surface)
    fig.subplots_adjust(left=0.06, right=0.95, bottom=0.12, top=0.9, wspace=0.18)
    return fig


def _contours(ax, run, first, second, values):
    """The objective's filled contours over two parameters (log-spaced where it spans a decade), the best search's
    path from its start, the optimum (a star) and any other optima found (crosses)."""
    from matplotlib.colors import LogNorm

    finite = values[np.isfinite(values)]
    low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    spans_decade = low > 0 and high > 10 * low
    levels = np.geomspace(low, high, 21) if spans_decade else np.linspace(low, max(high, low + 1e-300), 21)
    filled = ax.contourf(first, second, values, levels=levels, cmap="viridis",
                         norm=LogNorm(low, high) if spans_decade else None)
    ax.contour(first, second, values, levels=levels[::4], colors="white", linewidths=0.5, alpha=0.6)
    # the path as its improvements: each evaluation lower than every one before it (a line search's trials and
    # the refinement's differences left out)
    objective = run.history_objective
    improving = [i for i in range(len(objective)) if objective[i] < objective[:i].min(initial=np.inf)]
    path = run.history_parameters[improving]
    if len(path):
        ax.plot(path[:, 0], path[:, 1], "-", color="white", lw=1.0, alpha=0.9)
        ax.plot(path[0, 0], path[0, 1], "o", color="white", mec="black", ms=6, label="start", clip_on=False)
    for other, _ in run.optima[1:]:
        ax.plot(other[0], other[1], "x", color="C1", ms=8, mew=2, clip_on=False)
    ax.plot(run.optimum[0], run.optimum[1], "*", color="C3", mec="white", ms=14, label="optimum", clip_on=False)
    ax.set_xlim(run.lower[0], run.upper[0])
    ax.set_ylim(run.lower[1], run.upper[1])
    ax.set_xlabel(run.parameter[0])
    ax.set_ylabel(run.parameter[1])
    bar = ax.figure.colorbar(filled, ax=ax, ticks=levels[::4])
    bar.ax.set_yticklabels([f"{v:.3g}" for v in levels[::4]])
    bar.ax.minorticks_off()
    bar.set_label(run.objective + ("" if run.units == "1" else f" [{run.units}]"))
    ax.legend(fontsize=8, loc="best")


def receptance_curve(run, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|H_dof(w)| (or under support motion the transmissibility |T_dof(w)|) of the scene at these parameter values,
    on a grid over its peaks."""
    from smdcli.model import build
    from smdcli.sweep.frequency import receptance, transmissibility
    from smdcli.sweep.family import scenario_with

    model = build(scenario_with(run.sc, dict(zip(run.parameter, map(float, values))))).dense()
    top = max(float(np.concatenate([run.peaks[:, 0], run.peaks_before[:, 0]]).max(initial=0.0)), 1e-6)
    omega = np.linspace(0.0, 2.0 * top, 2000)
    if run.objective.startswith("peak_transmissibility"):
        H = transmissibility(model.M[None], model.C[None], model.K[None], omega)[0][0]
    else:
        H = receptance(model.M[None], model.C[None], model.K[None], omega, run.input_dof)[0]
    dof = run.sc.dof_names.index(run.objective.partition(":")[2])
    return omega, np.abs(H[:, dof])
