"""compare-solvers' charts: error against cost (work-precision), growth against step (stability).

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import math

from smdcli.plots.common import _figure, _wrap



def _method_styles(methods: list[str]) -> dict[str, dict]:
    """A fixed colour and marker per method, so both panels and both charts agree."""
    markers = "osD^v<>pPhX*"
    return {m: {"color": f"C{i % 10}", "marker": markers[i % len(markers)]} for i, m in enumerate(methods)}


def _two_panels(runs):
    """The methods in run order, their styles, and a figure of two panels sharing y with room for a legend."""
    methods = list(dict.fromkeys(r.method for r in runs))
    fig = _figure(figsize=(12, 6))
    axes = fig.subplots(1, 2, sharey=True)
    fig.subplots_adjust(left=0.07, right=0.8, top=0.86, bottom=0.1, wspace=0.06)
    return methods, _method_styles(methods), fig, axes


def _span_decades(ax, decades: float = 1.5) -> None:
    """Widen a log x axis to span at least `decades` about its middle (a power of ten at least is labelled) and label
    no minor tick: on a narrow axis matplotlib labels them, and those labels run into each other."""
    from matplotlib.ticker import NullFormatter

    low, high = ax.get_xlim()
    if low > 0 and high / low < 10 ** decades:
        middle = math.sqrt(low * high)
        ax.set_xlim(middle / 10 ** (decades / 2), middle * 10 ** (decades / 2))
    ax.xaxis.set_minor_formatter(NullFormatter())


def _in_band(low: float, index: int, count: int) -> float:
    """Where method `index` of `count` draws its failed runs in a failure band from low to 10 low (log axis): each
    method at its own height, so that crosses of two methods at one cost do not hide each other."""
    return low * 10 ** ((index + 1) / (count + 1))


def _band(ax, low: float, runs) -> None:
    """The grey failure band from low to 10 low, and its legend entry (no text in the plot: crosses go anywhere);
    nothing where no run failed."""
    if not any(_failed(r) for r in runs):
        return
    ax.axhspan(low, 10 * low, color="0.9", zorder=0)
    ax.plot([], [], "x", color="0.3", ms=8, mew=2, label="failed run (grey band);\nthe reason in the table")


def _failed(run) -> bool:
    """A run the charts cross out: it failed (diverged, energy created, a solver error), and was not skipped."""
    return not run.success and not run.message.startswith("skipped")


def work_precision_figure(comparison, title: str):
    """Error against wall time and against RHS evaluations, log-log, one line per method; failures as crosses."""
    runs = comparison.runs
    methods, styles, fig, axes = _two_panels(runs)
    worst = max((r.error for r in runs if r.success and math.isfinite(r.error)), default=1.0)
    band = 10 ** math.ceil(math.log10(max(worst, 1.0) * 1.5))  # above every good run: failures only
    costs = (("wall_time_s", "Wall time [s] (median of repeats)"), ("nfev", "Right-hand-side evaluations"))
    for ax, (cost, label) in zip(axes, costs):
        for i, m in enumerate(methods):
            mine = [r for r in runs if r.method == m]
            ok = [r for r in mine if r.success and getattr(r, cost) > 0]
            fixed = not mine[0].adaptive
            style = styles[m]
            if ok:
                ax.plot([getattr(r, cost) for r in ok], [max(r.error, 1e-17) for r in ok], ls="--" if fixed else "-",
                        lw=1.2, ms=5, label=m + (" (fixed step)" if fixed else ""), **style)
            else:
                ax.plot([], [], ls="--" if fixed else "-", label=f"{m} (all failed)", **style)
            bad = [r for r in mine if _failed(r) and getattr(r, cost) > 0]
            if bad:
                ax.plot([getattr(r, cost) for r in bad], [_in_band(band, i, len(methods))] * len(bad), "x",
                        color=style["color"], ms=8, mew=2)
        exact = comparison.exact_point
        if exact is not None and cost == "wall_time_s":
            how = "matrix exponential" if comparison.model.is_linear else "event to event"
            ax.plot([exact[0]], [max(exact[1], 1e-17)], "*", color="black", ms=14, zorder=5,
                    label=f"exact ({how}):\nits stated accuracy")
        ax.set_xscale("log")
        _span_decades(ax)
        ax.set_yscale("log")
        _band(ax, band, runs)
        ax.set_xlabel(label)
        ax.grid(True, which="major", alpha=0.4)
    axes[0].set_ylabel("Error: max |x - x_ref| / peak |x_ref|")
    if any(_failed(r) for r in runs):
        axes[0].set_ylim(top=10 * band)
    handles, labels = axes[0].get_legend_handles_labels()
    axes[1].legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    ref = f"reference: {comparison.reference_method}"
    if comparison.reference_error:
        ref += f" (own error {comparison.reference_error:.1e})"
    extra = "" if comparison.breakpoints else "; integration NOT restarted at force discontinuities"
    fig.suptitle(_wrap(f"{title}\nwork-precision: solid adaptive (one point per rtol), dashed fixed step (one per h); "
                       f"{ref}{extra}", 150), fontsize=10)
    return fig


def energy_precision_figure(comparison, title: str):
    """Each run's energy balance residual against its wall time, and against its true error: the check a run
    can make on itself, beside what only a reference can tell. Failed runs are crosses in a band, as on the
    work-precision chart."""
    runs = [r for r in comparison.runs if r.success and math.isfinite(r.energy_residual)]
    methods, styles, fig, axes = _two_panels(comparison.runs)
    worst = max((r.energy_residual for r in runs), default=1.0)
    band = 10 ** math.ceil(math.log10(max(worst, 1.0) * 1.5))
    for ax, (cost, label) in zip(axes, (("wall_time_s", "Wall time [s] (median of repeats)"),
                                        ("error", "Error: max |x - x_ref| / peak |x_ref|"))):
        for i, m in enumerate(methods):
            mine = [r for r in runs if r.method == m and getattr(r, cost) > 0]
            fixed = not next(r for r in comparison.runs if r.method == m).adaptive
            ax.plot([getattr(r, cost) for r in mine], [max(r.energy_residual, 1e-17) for r in mine],
                    ls="--" if fixed else "-", lw=1.2, ms=5, label=m + (" (fixed step)" if fixed else ""), **styles[m])
            bad = [r for r in comparison.runs if r.method == m and _failed(r)
                   and math.isfinite(getattr(r, cost)) and getattr(r, cost) > 0]
            if bad:
                ax.plot([getattr(r, cost) for r in bad], [_in_band(band, i, len(methods))] * len(bad), "x",
                        color=styles[m]["color"], ms=8, mew=2)
        ax.set_xscale("log")
        ax.set_yscale("log")
        _span_decades(ax)
        _band(ax, band, comparison.runs)
        ax.set_xlabel(label)
        ax.grid(True, which="major", alpha=0.4)
    if any(_failed(r) for r in comparison.runs):
        axes[0].set_ylim(top=10 * band)
    low, high = axes[1].get_xlim()
    axes[1].plot([low, high], [low, high], color="0.5", lw=0.8, ls=":", label="residual = error")
    axes[1].set_xlim(low, high)
    axes[0].set_ylabel("Energy residual / largest energy (the run's own check)")
    handles, labels = axes[1].get_legend_handles_labels()
    axes[1].legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    fig.suptitle(_wrap(f"{title}\nenergy balance of each run: kinetic + strain - initial + dissipated - input, "
                       f"against cost and against the error from the reference ({comparison.reference_method})", 150),
                 fontsize=10)
    return fig


GROWTH_BAND = 1e9  # diverged runs (stopped past 1e8 times their scale) are crosses in a band from here to 1e10


def stability_figure(comparison, title: str, limits: dict[str, float]):
    """Fixed-step growth (peak |x| / reference peak) against h * omega_max, each method's undamped limit drawn."""
    runs = [r for r in comparison.runs if not r.adaptive and math.isfinite(r.h_omega)]
    methods = list(dict.fromkeys(r.method for r in comparison.runs))
    styles = _method_styles(methods)
    fig = _figure(figsize=(10, 6))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.09, right=0.72, top=0.86, bottom=0.1)
    fixed_methods = list(dict.fromkeys(r.method for r in runs))
    for i, m in enumerate(fixed_methods):
        mine = sorted((r for r in runs if r.method == m), key=lambda r: r.h_omega)
        style = styles[m]
        ok = [r for r in mine if r.success]
        ax.plot([r.h_omega for r in ok], [r.growth for r in ok], "-", lw=1.2, ms=5, label=m, **style)
        bad = [r for r in mine if _failed(r)]
        if bad:
            ax.plot([r.h_omega for r in bad], [_in_band(GROWTH_BAND, i, len(fixed_methods))] * len(bad), "x",
                    color=style["color"], ms=9, mew=2)
        limit = limits.get(m, math.inf)
        if 0 < limit < math.inf:
            ax.axvline(limit, color=style["color"], ls=":", lw=1.5)
            # In the band above the data, where no run is drawn: the label never covers a curve.
            ax.text(limit, 0.985, f"{m} limit {limit:.3g} ", transform=ax.get_xaxis_transform(), rotation=90,
                    va="top", ha="right", fontsize=7, color=style["color"])
    notes = [f"{m}: {'unconditionally stable' if limits.get(m, math.inf) == math.inf else 'unstable at any h'}"
             for m in dict.fromkeys(r.method for r in runs) if limits.get(m, math.inf) in (0.0, math.inf)]
    if any(r.h_omega > 0 for r in runs):  # a scene at rest has no omega_max: nothing on a log axis
        ax.set_xscale("log")
    grown = [r.growth for r in runs if r.success and r.growth > 0]
    ax.set_ylim(min(0.1, min(grown, default=0.1) / 2), 1e10)  # limits first: a scene at rest has no positive growth
    ax.set_yscale("log")
    _band(ax, GROWTH_BAND, runs)
    ax.axhline(1.0, color="k", lw=0.8, alpha=0.5)
    ax.set_ylim(top=1e13)  # room above the band for the limits' labels
    ax.set_xlabel(f"Step times highest natural frequency, h·ω_max [1]  (ω_max = {comparison.omega_max:.4g} rad/s)")
    ax.set_ylabel("Growth: peak |x| of the run / peak |x| of the reference [1]")
    ax.grid(True, which="major", alpha=0.4)
    handles = ax.get_legend_handles_labels()
    ax.legend(*handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False,
              title="dotted: stability limit\n(undamped theory)")
    if notes:
        ax.text(1.02, 0.0, "\n".join(notes), transform=ax.transAxes, fontsize=8, va="bottom")
    fig.suptitle(f"{title}\nstability of fixed-step methods: a bounded run stays near 1", fontsize=10)
    return fig


# What each verdict looks like on the failure map of a nonsmooth scene.
VERDICTS = (("ok", "#4c9a5b"), ("missed", "#d62728"), ("chattered", "#ff7f0e"), ("energy", "#9467bd"),
            ("wrong law", "#e377c2"), ("another law", "#17becf"), ("diverged", "#8c564b"),
            ("too many steps", "#bcbd22"), ("failed", "#7f7f7f"), ("cannot represent", "#e6e6e6"))


def _verdict(run) -> str:
    if run.success:
        return "ok"
    for word in ("missed", "chattered", "energy", "wrong law", "diverged", "cannot represent"):
        if run.message.startswith(word):
            return word
    if run.message.startswith("converges to another law"):
        return "another law"
    if run.message.startswith("skipped: needs") or "steps" in run.message:
        return "too many steps"
    return "failed"


def failure_map_figure(comparison, title: str):
    """A nonsmooth scene: each method (rows) at each tolerance or step (columns), coloured by what happened (events
    missed, a stick that chattered, energy created, a smoothed law that changed the scene, divergence, a step budget
    spent), its error and steps written in."""
    from matplotlib.patches import Patch, Rectangle

    runs = comparison.runs  # a rung skipped for its step count is one too: the budget is what it would exceed
    methods = list(dict.fromkeys(r.method for r in runs))
    settings = sorted({(r.rtol if r.adaptive else r.dt) for r in runs}, reverse=True)
    width, rows = max(9.0, 1.6 * len(settings) + 3.5), 0.42 * len(methods)
    top, bottom = 0.8, 1.3 + (0.45 if comparison.refused else 0.0)  # inches: the title; the axis label, legend, notes
    height = rows + top + bottom
    fig = _figure(figsize=(width, height))
    ax = fig.subplots()
    fig.subplots_adjust(left=1.6 / width, right=1 - 0.2 / width, top=1 - top / height, bottom=bottom / height)
    colours = dict(VERDICTS)
    for i, method in enumerate(methods):
        for r in (r for r in runs if r.method == method):
            j = settings.index(r.rtol if r.adaptive else r.dt)
            kind = _verdict(r)
            ax.add_patch(Rectangle((j, i), 1, 1, facecolor=colours[kind], edgecolor="white"))
            text = f"{r.error:.0e}\n{r.steps_accepted} st" if kind == "ok" else \
                kind.replace("too many ", "too many\n").replace("cannot ", "cannot\n").replace("another ", "another\n") \
                + (f"\n{r.error:.0e}" if kind in ("wrong law", "another law") else "")
            ax.text(j + 0.5, i + 0.5, text, ha="center", va="center", fontsize=6.5,
                    color="white" if kind not in ("cannot represent",) else "0.3")
    ax.set_xlim(0, len(settings))
    ax.set_ylim(len(methods), 0)
    ax.set_xticks([j + 0.5 for j in range(len(settings))])
    ax.set_xticklabels([f"{s:.0e}" for s in settings], fontsize=8)
    ax.set_yticks([i + 0.5 for i in range(len(methods))])
    ax.set_yticklabels(methods, fontsize=8)
    ax.set_xlabel("rtol (adaptive methods) or step [s] (fixed-step methods)")
    handles = [Patch(color=c, label=k) for k, c in VERDICTS]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.55 / rows), ncol=len(VERDICTS),
              fontsize=7, frameon=False, bbox_transform=ax.transAxes, handlelength=1.5, columnspacing=1.0)
    if comparison.refused:  # methods that cannot take the scene at all, grouped by why
        groups: dict[str, list[str]] = {}
        for method, reason in comparison.refused.items():
            element, _, why = reason.removeprefix("cannot represent: ").partition(": ")
            why = why.split(";")[0].split(":")[0].removeprefix(repr(method)).strip()
            groups.setdefault(f"{why} ({element})", []).append(method)
        text = "; ".join(f"{', '.join(methods)} {why}" for why, methods in groups.items())
        fig.text(0.02, 0.1 / height, _wrap(f"cannot represent it (not run): {text}", int(width * 17)), fontsize=7,
                 va="bottom")
    events = len(comparison.reference.nonsmooth.events) if comparison.reference.nonsmooth is not None else 0
    fig.suptitle(f"{title}\nwhere each method fails, against the exact event-driven solution ({events} events); "
                 "ok cells: error over the peak and steps", fontsize=9)
    return fig
