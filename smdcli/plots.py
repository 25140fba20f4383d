"""Figures from Results. Plot functions return a Figure; only save_figure touches disk."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from smdcli.result import Result
from smdcli.sweep import parameter_label


def _figure(**kwargs):
    """A Figure on the Agg canvas, without pyplot's global state (and its import cost)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


MAX_DRAWN = 2000  # points per line: about two per pixel column of the axes


def envelope(t: np.ndarray, y: np.ndarray, max_points: int = MAX_DRAWN) -> tuple[np.ndarray, np.ndarray]:
    """Thin a long series to min/max pairs per bucket, in time order: the drawn line looks the same."""
    n = len(t)
    if n <= max_points:
        return t, y
    buckets = max_points // 2
    edges = np.linspace(0, n, buckets + 1).astype(int)
    arg_lo = np.array([a + np.argmin(y[a:b]) for a, b in zip(edges[:-1], edges[1:])])
    arg_hi = np.array([a + np.argmax(y[a:b]) for a, b in zip(edges[:-1], edges[1:])])
    first = arg_lo <= arg_hi
    idx = np.empty(2 * buckets, dtype=int)
    idx[0::2] = np.where(first, arg_lo, arg_hi)
    idx[1::2] = np.where(first, arg_hi, arg_lo)
    return t[idx], y[idx]


def _band(t: np.ndarray, y: np.ndarray, max_points: int = MAX_DRAWN):
    """For a series that oscillates faster than the axes can draw (a 120 rad/s force over 120 s): per-bucket
    (times, low, high, mean), so the plot shows the band it fills and the motion it rides on; None otherwise."""
    n = len(t)
    if n <= max_points:
        return None
    dy = np.diff(y)
    turns = np.count_nonzero(np.sign(dy[1:]) * np.sign(dy[:-1]) < 0)
    buckets = max_points // 2
    if turns < 2 * buckets:  # fewer than one oscillation per bucket: a line shows it
        return None
    edges = np.linspace(0, n, buckets + 1).astype(int)
    low = np.minimum.reduceat(y, edges[:-1])
    high = np.maximum.reduceat(y, edges[:-1])
    # The running mean over two buckets, twice (a triangular window): a plain bucket mean of an oscillation
    # that does not fit a bucket a whole number of times aliases into wiggles that are not in the motion.
    width = max(1, n // buckets)
    mean = _running_mean(_running_mean(y, width), width)
    centres = np.minimum((edges[:-1] + edges[1:]) // 2, n - 1)
    return t[edges[:-1]], low, high, mean[centres]


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
    turns = 0
    for data in (result.displacement, result.acceleration):
        dy = np.diff(data, axis=0)
        turns = max(turns, int((np.sign(dy[1:]) * np.sign(dy[:-1]) < 0).sum(axis=0).max()))
    if turns < MAX_DRAWN // 2:
        return None
    width = min(10 * (t[-1] - t[0]) / turns, (t[-1] - t[0]) / 10)  # two turns a period: five periods
    return t[-1] - width, t[-1]


FORCE_STYLES = ("-", "--", ":", "-.")


def response_figure(result: Result, title: str):
    """Applied forces, then displacement, velocity and acceleration against time, one colour per DOF.

    An oscillation too fast to draw over the whole run is shown as a faint band (its range) with its running
    mean, and a zoomed inset shows its last few periods."""
    forced = np.any(result.force != 0)
    rows = (("force", "Force F [N]"),) if forced else ()
    rows += (("displacement", "Displacement x [m]"), ("velocity", "Velocity v [m/s]"),
             ("acceleration", "Acceleration a [m/s²]"))
    heights = [0.55 if name == "force" else 1.0 for name, _ in rows]
    fig = _figure(figsize=(9, 2.6 * sum(heights) + 1.2))
    axes = fig.subplots(len(rows), 1, sharex=True, gridspec_kw={"height_ratios": heights})
    fig.subplots_adjust(left=0.1, right=0.97, top=0.9, bottom=0.07, hspace=0.12)
    window = _fast_window(result)
    banded = set()
    for ax, (name, label) in zip(axes, rows):
        data = getattr(result, name)
        for j, dof in enumerate(result.dofs):
            if name == "force":
                if not np.any(data[:, j] != 0):
                    continue
                style = FORCE_STYLES[len(ax.get_lines()) % len(FORCE_STYLES)]
                band = _band(result.time, data[:, j])
                if band is not None:
                    ax.fill_between(band[0], band[1], band[2], color=f"C{j}", alpha=0.25, lw=0,
                                    label=f"F on {dof} (range of a fast oscillation)")
                else:
                    ax.plot(*envelope(result.time, data[:, j]), ls=style, lw=1.2, color=f"C{j}", label=f"F on {dof}")
                continue
            band = _band(result.time, data[:, j])
            if band is None:
                ax.plot(*envelope(result.time, data[:, j]), lw=1.1, color=f"C{j}", label=dof)
            else:
                banded.add(dof)
                ax.fill_between(band[0], band[1], band[2], color=f"C{j}", alpha=0.22, lw=0)
                ax.plot(band[0], band[3], lw=1.1, color=f"C{j}", label=dof)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.4)
        if name == "force":
            ax.legend(loc="upper right", fontsize=8, framealpha=0.85)
        if window is not None and name == "acceleration":
            _zoom_inset(ax, result, data, window)
    motion = axes[1] if forced else axes[0]
    handles, labels = motion.get_legend_handles_labels()
    if banded:
        from matplotlib.patches import Patch

        handles.append(Patch(color="0.6", alpha=0.35, lw=0))
        labels.append("shaded: range of an oscillation too fast to draw (line: its running mean)")
    motion.legend(handles, labels, loc="upper right", fontsize=8, framealpha=0.85, ncol=1)
    axes[-1].set_xlabel("Time t [s]")
    axes[0].set_xlim(result.time[0], result.time[-1])
    fig.suptitle(title, fontsize=11)
    return fig


def _zoom_inset(ax, result: Result, data: np.ndarray, window: tuple[float, float]) -> None:
    """The last few periods of the fastest oscillation, drawn in full, in an inset of `ax`."""
    inset = ax.inset_axes((0.56, 0.56, 0.42, 0.4))
    keep = (result.time >= window[0]) & (result.time <= window[1])
    for j, dof in enumerate(result.dofs):
        inset.plot(result.time[keep], data[keep, j], lw=0.9, color=f"C{j}")
    from matplotlib.ticker import MaxNLocator

    inset.set_xlim(*window)
    inset.tick_params(labelsize=7)
    inset.xaxis.set_major_locator(MaxNLocator(3))
    inset.ticklabel_format(axis="x", useOffset=False)
    inset.yaxis.set_major_locator(MaxNLocator(3))
    inset.text(0.02, 0.96, f"zoom on the last {window[1] - window[0]:.3g} s, every sample", transform=inset.transAxes,
               fontsize=7, va="top", bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1})
    inset.grid(True, alpha=0.3)
    inset.set_facecolor("white")


def phase_figure(result: Result, title: str):
    """Phase portrait of a run: velocity against displacement per DOF, start and direction marked."""
    curves = [(dof, result.displacement[:, j], result.velocity[:, j]) for j, dof in enumerate(result.dofs)]
    return portrait_figure(curves, f"{title}\nphase portrait")


FAILED_LEVEL = 3.0  # failed runs are drawn as crosses on a band above error = 1


def _method_styles(methods: list[str]) -> dict[str, dict]:
    """A fixed colour and marker per method, so both panels and both charts agree."""
    markers = "osD^v<>pPhX*"
    return {m: {"color": f"C{i % 10}", "marker": markers[i % len(markers)]} for i, m in enumerate(methods)}


def work_precision_figure(comparison, title: str):
    """Error against wall time and against RHS evaluations, log-log, one line per method; failures as crosses."""
    runs = comparison.runs
    methods = list(dict.fromkeys(r.method for r in runs))
    styles = _method_styles(methods)
    fig = _figure(figsize=(12, 6))
    axes = fig.subplots(1, 2, sharey=True)
    fig.subplots_adjust(left=0.07, right=0.8, top=0.86, bottom=0.1, wspace=0.06)
    costs = (("wall_time_s", "Wall time [s] (median of repeats)"), ("nfev", "Right-hand-side evaluations"))
    for ax, (cost, label) in zip(axes, costs):
        for m in methods:
            mine = [r for r in runs if r.method == m]
            ok = [r for r in mine if r.success and r.error < 1.0 and getattr(r, cost) > 0]
            fixed = not mine[0].adaptive
            style = styles[m]
            if ok:
                ax.plot([getattr(r, cost) for r in ok], [max(r.error, 1e-17) for r in ok], ls="--" if fixed else "-",
                        lw=1.2, ms=5, label=m + (" (fixed step)" if fixed else ""), **style)
            else:
                ax.plot([], [], ls="--" if fixed else "-", label=f"{m} (all failed)", **style)
            bad = [r for r in mine if (not r.success or r.error >= 1.0) and getattr(r, cost) > 0]
            if bad:
                ax.plot([getattr(r, cost) for r in bad], [FAILED_LEVEL] * len(bad), "x", color=style["color"], ms=8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.axhspan(1.0, 10.0, color="0.9", zorder=0)
        ax.text(0.99, 1.15, "band: failed, or error >= 1 (x)", transform=ax.get_yaxis_transform(), ha="right",
                va="bottom", fontsize=7, color="0.35")
        ax.set_xlabel(label)
        ax.grid(True, which="major", alpha=0.4)
    axes[0].set_ylabel("Error: max |x - x_ref| / peak |x_ref|")
    axes[0].set_ylim(top=10.0)
    axes[1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    ref = f"reference: {comparison.reference_method}"
    if comparison.reference_error:
        ref += f" (own error {comparison.reference_error:.1e})"
    extra = "" if comparison.breakpoints else "; integration NOT restarted at force discontinuities"
    fig.suptitle(f"{title}\nwork-precision: solid adaptive (one point per rtol), dashed fixed step (one per h); "
                 f"{ref}{extra}", fontsize=10)
    return fig


GROWTH_FAILED = 3e9  # diverged runs (stopped past 1e8 times their scale) are crosses in a band up here


def stability_figure(comparison, title: str, limits: dict[str, float]):
    """Fixed-step growth (peak |x| / reference peak) against h * omega_max, each method's undamped limit drawn."""
    runs = [r for r in comparison.runs if not r.adaptive and math.isfinite(r.h_omega)]
    methods = list(dict.fromkeys(r.method for r in comparison.runs))
    styles = _method_styles(methods)
    fig = _figure(figsize=(10, 6))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.09, right=0.72, top=0.86, bottom=0.1)
    for m in dict.fromkeys(r.method for r in runs):
        mine = sorted((r for r in runs if r.method == m), key=lambda r: r.h_omega)
        style = styles[m]
        ok = [r for r in mine if r.success]
        ax.plot([r.h_omega for r in ok], [r.growth for r in ok], "-", lw=1.2, ms=5, label=m, **style)
        bad = [r for r in mine if not r.success and not r.message.startswith("skipped")]
        if bad:
            ax.plot([r.h_omega for r in bad], [GROWTH_FAILED] * len(bad), "x", color=style["color"], ms=9, mew=2)
        limit = limits.get(m, math.inf)
        if 0 < limit < math.inf:
            ax.axvline(limit, color=style["color"], ls=":", lw=1.5)
            # In the band above the data, where no run is drawn: the label never covers a curve.
            ax.text(limit, 0.985, f"{m} limit {limit:.3g} ", transform=ax.get_xaxis_transform(), rotation=90,
                    va="top", ha="right", fontsize=7, color=style["color"])
    notes = [f"{m}: {'unconditionally stable' if limits.get(m, math.inf) == math.inf else 'unstable at any h'}"
             for m in dict.fromkeys(r.method for r in runs) if limits.get(m, math.inf) in (0.0, math.inf)]
    ax.set_xscale("log")
    ax.set_yscale("log")
    grown = [r.growth for r in runs if r.success and r.growth > 0]
    ax.set_ylim(min(0.1, min(grown, default=0.1) / 2), 1e10)
    ax.axhspan(1e9, 1e10, color="0.9", zorder=0)
    ax.axhline(1.0, color="k", lw=0.8, alpha=0.5)
    ax.set_ylim(top=1e13)  # room above the band for the limits' labels
    ax.text(0.01, 1.1e9, "band: diverged or failed (x)", transform=ax.get_yaxis_transform(), ha="left",
            va="bottom", fontsize=7, color="0.35")
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


# ------------------------------------------------------------------ sweeps

MAX_LEGEND = 12  # beyond this many members, a colour bar replaces the legend
MAX_LINES = 300  # members drawn in an overlay; more would be slow and look the same
QUANTITY_LABELS = {"displacement": "Displacement x [m]", "velocity": "Velocity v [m/s]",
                   "acceleration": "Acceleration a [m/s²]", "force": "Applied force F [N]"}
METRIC_LABELS = {"peak_displacement": "peak |x| [m]", "rms_displacement": "RMS x [m]",
                 "settling_time": "settling time to 2 % [s]", "peak_ground_force": "peak force to ground [N]"}
_STYLES = ("-", "-.", ":", "--")


def _member_colors(count: int):
    """A colour per member: the cycle for a legend's worth, a colour map beyond."""
    if count <= MAX_LEGEND:
        return [f"C{i % 10}" for i in range(count)], None
    from matplotlib import colormaps

    cmap = colormaps["viridis"]
    return [cmap(i / max(count - 1, 1)) for i in range(count)], cmap


def overlay_figure(family, result, quantity: str, title: str):
    """One panel per DOF, one line per member of the family, with a legend (or a colour bar for many)."""
    data = getattr(result, quantity)
    S, N, n = data.shape
    colors, cmap = _member_colors(S)
    height = 2.2 + 2.6 * n
    fig = _figure(figsize=(9, height))
    axes = np.atleast_1d(fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0])
    fig.subplots_adjust(left=0.1, right=0.8 if cmap is None else 0.86, top=1 - 0.75 / height, bottom=0.55 / height,
                        hspace=0.12)
    drawn = np.unique(np.linspace(0, S - 1, min(S, MAX_LINES)).round().astype(int))
    for j, ax in enumerate(axes):
        for s in drawn:
            t = result.time if result.time.ndim == 1 else result.time[s]
            ok = np.isfinite(t)
            style = _STYLES[s % len(_STYLES)] if cmap is None else "-"
            ax.plot(*envelope(t[ok], data[s, ok, j]), style, lw=1.4 if cmap is None else 0.8, color=colors[s],
                    label=family.labels[s])
            if not result.success[s]:
                ax.plot(t[ok][-1], data[s, ok, j][-1], "x", color=colors[s], ms=8)
        ax.set_ylabel(f"{result.dofs[j]}: {QUANTITY_LABELS[quantity]}", fontsize=9)
        ax.grid(True, alpha=0.4)
    axes[-1].set_xlabel("Time t [s]")
    if cmap is None:
        axes[0].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    else:
        _colorbar(fig, axes, cmap, family)
    shown = f" ({len(drawn)} of them drawn, evenly spaced)" if len(drawn) < S else ""
    fig.suptitle(_wrap(f"{title}\n{S} runs{shown}: {result.how}", 100), fontsize=10)
    return fig


def _colorbar(fig, axes, cmap, family):
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    values = family.values[:, 0] if family.values.shape[1] else np.arange(len(family))
    mappable = ScalarMappable(norm=Normalize(values.min(), values.max()), cmap=cmap)
    bar = fig.colorbar(mappable, ax=list(axes), fraction=0.04, pad=0.02)
    bar.set_label(parameter_label(family.spec.parameters[0]) if family.spec.parameters else "member")


def metric_figure(family, values: np.ndarray, metric: str, dofs, title: str):
    """A metric per DOF: against the parameter (one parameter) or as a heat map over the grid (two)."""
    n = values.shape[1]
    params = family.spec.parameters
    if len(params) == 2:
        fig = _figure(figsize=(5.2 * min(n, 3), 4.6 * math.ceil(n / 3)))
        axes = np.atleast_1d(fig.subplots(math.ceil(n / 3), min(n, 3), squeeze=False).ravel())
        fig.subplots_adjust(left=0.1, right=0.95, top=0.8, bottom=0.12, wspace=0.35, hspace=0.35)
        a, b = family.spec.values
        for j in range(n):
            ax = axes[j]
            grid = values[:, j].reshape(len(a), len(b)).T
            mesh = ax.pcolormesh(a, b, grid, shading="nearest", cmap="viridis")
            fig.colorbar(mesh, ax=ax).set_label(METRIC_LABELS[metric])
            ax.set_xlabel(parameter_label(params[0]))
            ax.set_ylabel(parameter_label(params[1]))
            ax.set_title(str(dofs[j]), fontsize=9)
        for ax in axes[n:]:
            ax.set_visible(False)
    else:
        fig = _figure(figsize=(8, 5))
        ax = fig.subplots()
        fig.subplots_adjust(left=0.12, right=0.95, top=0.86, bottom=0.12)
        x = family.values[:, 0] if params else np.arange(len(family))
        order = np.argsort(x, kind="stable")
        finite = values[np.isfinite(values)]
        top = finite.max() * 1.05 if finite.size else 1.0
        for j in range(n):
            ax.plot(x[order], values[order, j], "o-", ms=4, lw=1.2, label=str(dofs[j]), color=f"C{j}")
            missing = ~np.isfinite(values[:, j])
            if missing.any():
                ax.plot(x[missing], np.full(missing.sum(), top), "x", ms=8, mew=2, color=f"C{j}")
        if (~np.isfinite(values)).any():  # its own legend entry: not a value, a verdict
            ax.plot([], [], "x", ms=8, mew=2, color="0.3",
                    label="not settled by the end of the run" if metric == "settling_time" else "no value")
        ax.set_xlabel(parameter_label(params[0]) if params else "member")
        ax.set_ylabel(METRIC_LABELS[metric])
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=8, loc="best")
    fig.suptitle(f"{title}\n{METRIC_LABELS[metric]} of every run", fontsize=10)
    return fig


def frequency_figure(family, response, title: str, unit: str = "rad/s", normalized: bool = False):
    """Amplitude (log) and phase lag against frequency: one line per member and DOF, resonance peaks marked.

    Normalized (1-DOF): X K / F0 and theta against r = omega / omega_n, as the book's Figures 9-9 and 9-10.
    Measured responses (nonlinear, or on request) are drawn as markers, up sweeps and down sweeps apart.
    """
    S, F, n = response.amplitude.shape
    colors, cmap = _member_colors(S * n if S == 1 else S)
    fig = _figure(figsize=(9.5, 8))
    ax_a, ax_p = fig.subplots(2, 1, sharex=True)
    fig.subplots_adjust(left=0.1, right=0.95 if cmap is None else 0.86, top=0.88, bottom=0.08, hspace=0.08)
    k = family.K[:, 0, 0] if normalized else np.ones(S)  # amplitude scale: X K / F0, or m/N
    # the x axis per member: r = omega / omega_n, or the frequency in the unit it was given in
    per = np.sqrt(family.K[:, 0, 0] / family.M[:, 0, 0]) if normalized else \
        np.full(S, 2 * math.pi if unit == "Hz" else 1.0)
    markers = {"up": "^", "down": "v"}
    # A measured response's two sweeps in colours of their own, so the branches of a jump tell apart.
    direction_colors = {"up": "tab:red", "down": "tab:blue"}
    for s in range(S):
        for j in range(n):
            color = colors[s] if S > 1 else colors[j]
            label = family.labels[s] if n == 1 else (f"{response.dofs[j]}" if S == 1 else f"{family.labels[s]}: {response.dofs[j]}")
            style = _STYLES[(s if S > 1 else j) % len(_STYLES)] if cmap is None else "-"
            x = response.omega / per[s]
            if response.exact:
                with np.errstate(all="ignore"):
                    ax_a.plot(x, response.amplitude[s, :, j] * k[s], style, color=color, lw=1.4, label=label)
                    ax_p.plot(x, response.phase[s, :, j], style, color=color, lw=1.4)
            for direction, (amp, lag) in response.measured.items():
                if response.exact:  # markers over the exact lines, labelled once
                    tag = f"simulated, sweep {direction}" if s == 0 and j == 0 else None
                else:
                    tag = f"sweep {direction}" + (f": {label}" if S > 1 or n > 1 else "")
                shade = direction_colors[direction] if S * n == 1 else color
                ax_a.plot(x, amp[s, :, j] * k[s], markers[direction], color=shade, ms=4, mfc="none",
                          ls="-" if not response.exact else "none", lw=0.8, label=tag)
                ax_p.plot(x, lag[s, :, j], markers[direction], color=shade, ms=4, mfc="none",
                          ls="-" if not response.exact else "none", lw=0.8)
    exact_peaks = [p for p in response.peaks if "direction" not in p]  # measured maxima are listed, not marked
    for peak in exact_peaks:
        s = peak["member"]
        w = peak["omega"] / per[s]
        if math.isfinite(peak["amplitude"]):
            ax_a.plot(w, peak["amplitude"] * k[s], "o", color="k", ms=5, mfc="none")
        else:
            ax_a.axvline(w, color="0.5", ls=":", lw=1)
    if any(math.isfinite(p["amplitude"]) for p in exact_peaks):
        ax_a.plot([], [], "o", color="k", mfc="none", label="resonance peak")
    if any(not math.isfinite(p["amplitude"]) for p in exact_peaks):
        ax_a.plot([], [], ":", color="0.5", label="undamped: unbounded")
    ax_a.set_yscale("log")
    if normalized:
        ax_a.set_ylabel("Normalized amplitude X K / F₀ [1]")
        ax_p.set_xlabel("Frequency ratio r = ω / ωₙ [1]")
    else:
        ax_a.set_ylabel(f"Amplitude per unit force on {response.input_dof} [m/N]")
        ax_p.set_xlabel(f"Forcing frequency {'f' if unit == 'Hz' else 'ω'} [{unit}]")
    finite = response.amplitude[np.isfinite(response.amplitude) & (response.amplitude > 0)]
    measured = [a[np.isfinite(a) & (a > 0)] for a, _ in response.measured.values()]
    pool = np.concatenate([finite] + measured) * k.max()
    if pool.size:
        ax_a.set_ylim(max(pool.min() / 2, pool.max() * 1e-6), pool.max() * 2)
    ax_p.set_ylabel("Phase lag θ [rad]")
    ticks = 5 if np.nanmax(response.phase, initial=0) > 3.3 else 3  # to 2 pi where a lag passes pi
    ax_p.set_yticks([i * math.pi / 2 for i in range(ticks)])
    ax_p.set_yticklabels(["0", "π/2", "π", "3π/2", "2π"][:ticks])
    for ax in (ax_a, ax_p):
        ax.grid(True, which="both", alpha=0.35)
    if cmap is None:
        ax_a.legend(loc="upper right", fontsize=8, framealpha=0.85)
    else:
        _colorbar(fig, [ax_a, ax_p], cmap, family)
    kind = "exact receptance (K - ω²M + iωC)⁻¹" if response.exact else "measured by simulation to steady state"
    extra = f"; measured vs exact: {response.difference:.1e} of the peak" if response.difference is not None else ""
    fig.suptitle(f"{title}\nfrequency response, {kind}{extra}", fontsize=10)
    return fig


def _wrap(text: str, width: int) -> str:
    """Break a long label or title line at spaces, keeping existing line breaks."""
    import textwrap

    return "\n".join(textwrap.fill(line, width) for line in text.split("\n"))


def portrait_figure(curves, title: str, poincare=None):
    """Phase portraits: velocity against displacement per curve (label, x, v), start marked, direction arrowed;
    Poincare points (label, x, v) drawn as dots."""
    fig = _figure(figsize=(7.5, 6.5))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.13, right=0.72, top=0.88, bottom=0.1)
    for i, (label, x, v) in enumerate(curves):
        color = f"C{i % 10}"
        faint = poincare is not None
        ax.plot(x, v, _STYLES[i % len(_STYLES)] if len(curves) <= 4 else "-", lw=0.6 if faint else 1.3, color=color,
                alpha=0.35 if faint else 1.0, label=_wrap(label, 32))
        ax.plot(x[0], v[0], "o", color=color, ms=7, mfc="white", mew=1.5)
        _direction_arrows(ax, x, v, color)
    if poincare is not None:
        for i, (label, x, v) in enumerate(poincare):
            ax.plot(x, v, "o", color=f"C{i % 10}", ms=6, mec="k", mew=0.6, zorder=5,
                    label=_wrap(f"{label}: once per period", 32))
    ax.plot([], [], "o", color="k", mfc="white", label="start")
    ax.set_xlabel("Displacement x [m]")
    ax.set_ylabel("Velocity v [m/s]")
    ax.grid(True, alpha=0.4)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax.set_title(_wrap(title, 80), fontsize=10)
    return fig


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


def save_figure(fig, path: Path) -> None:
    """Save a figure atomically as PNG and release it."""
    from smdcli.io_hdf5 import atomic_path

    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
