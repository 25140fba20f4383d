"""Figures from Results. Plot functions return a Figure; only save_figure touches disk."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from smdcli.result import Result


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


def _title(title: str, result: Result) -> str:
    return f"{title}\n{result.stats.method}: {result.stats.reason}" if len(result.stats.reason) < 90 else \
        f"{title}\n{result.stats.method}"


def response_figure(result: Result, title: str):
    """Displacement, velocity and acceleration against time, one line per DOF; force on a second axis."""
    fig = _figure(figsize=(9, 8.5))
    axes = fig.subplots(3, 1, sharex=True)
    fig.subplots_adjust(left=0.1, right=0.88, top=0.88, bottom=0.07, hspace=0.12)
    quantities = (("displacement", "Displacement x [m]"), ("velocity", "Velocity v [m/s]"),
                  ("acceleration", "Acceleration a [m/s²]"))
    for ax, (name, label) in zip(axes, quantities):
        data = getattr(result, name)
        for j, dof in enumerate(result.dofs):
            ax.plot(*envelope(result.time, data[:, j]), lw=1.1, label=dof, color=f"C{j}")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.4)
    forced = np.any(result.force != 0)
    if forced:
        twin = axes[0].twinx()
        for j, dof in enumerate(result.dofs):
            if np.any(result.force[:, j] != 0):
                twin.plot(*envelope(result.time, result.force[:, j]), lw=0.7, ls="--", color=f"C{j}", alpha=0.3,
                          label=f"F on {dof}")
        twin.set_ylabel("Applied force F [N] (dashed, faint)")
        # The force axis goes behind the displacements, which are what the panel is about.
        axes[0].set_zorder(twin.get_zorder() + 1)
        axes[0].patch.set_visible(False)
        lines = axes[0].get_lines() + twin.get_lines()
    else:
        lines = axes[0].get_lines()
    axes[0].legend(lines, [ln.get_label() for ln in lines], loc="lower left", bbox_to_anchor=(0.0, 1.0),
                   fontsize=8, ncol=min(len(lines), 6), frameon=False)
    axes[-1].set_xlabel("Time t [s]")
    axes[0].set_xlim(result.time[0], result.time[-1])
    fig.suptitle(_title(title, result), fontsize=10)
    return fig


def phase_figure(result: Result, title: str):
    """Phase portrait: velocity against displacement per DOF, start marked."""
    fig = _figure(figsize=(6.5, 6))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.14, right=0.96, top=0.88, bottom=0.1)
    for j, dof in enumerate(result.dofs):
        x, v = result.displacement[:, j], result.velocity[:, j]
        ax.plot(x, v, lw=0.9, color=f"C{j}", label=dof)
        ax.plot(x[0], v[0], "o", color=f"C{j}", ms=6, mfc="white")
    ax.plot([], [], "o", color="k", mfc="white", label="start")
    ax.set_xlabel("Displacement x [m]")
    ax.set_ylabel("Velocity v [m/s]")
    ax.grid(True, alpha=0.4)
    ax.legend(fontsize=8)
    ax.set_title(f"{title}\nphase portrait", fontsize=10)
    return fig


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
            ax.text(limit, 0.02, f" {m} limit {limit:.3g}", transform=ax.get_xaxis_transform(), rotation=90,
                    va="bottom", ha="right", fontsize=8, color=style["color"])
    notes = [f"{m}: {'unconditionally stable' if limits.get(m, math.inf) == math.inf else 'unstable at any h'}"
             for m in dict.fromkeys(r.method for r in runs) if limits.get(m, math.inf) in (0.0, math.inf)]
    ax.set_xscale("log")
    ax.set_yscale("log")
    grown = [r.growth for r in runs if r.success and r.growth > 0]
    ax.set_ylim(min(0.1, min(grown, default=0.1) / 2), 1e10)
    ax.axhspan(1e9, 1e10, color="0.9", zorder=0)
    ax.axhline(1.0, color="k", lw=0.8, alpha=0.5)
    ax.text(0.99, 1.1e9, "band: diverged or failed (x)", transform=ax.get_yaxis_transform(), ha="right",
            va="bottom", fontsize=7, color="0.35")
    ax.set_xlabel(f"Step times highest natural frequency, h * omega_max  (omega_max = {comparison.omega_max:.4g} rad/s)")
    ax.set_ylabel("Growth: peak |x| of the run / peak |x| of the reference")
    ax.grid(True, which="major", alpha=0.4)
    handles = ax.get_legend_handles_labels()
    ax.legend(*handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False,
              title="dotted: stability limit\n(undamped theory)")
    if notes:
        ax.text(1.02, 0.0, "\n".join(notes), transform=ax.transAxes, fontsize=8, va="bottom")
    fig.suptitle(f"{title}\nstability of fixed-step methods: a bounded run stays near 1", fontsize=10)
    return fig


def save_figure(fig, path: Path) -> None:
    """Save a figure atomically as PNG and release it."""
    from smdcli.io_hdf5 import atomic_path

    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
