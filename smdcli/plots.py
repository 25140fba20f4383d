"""Figures from Results. Plot functions return a Figure; only save_figure touches disk."""

from __future__ import annotations

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


def save_figure(fig, path: Path) -> None:
    """Save a figure atomically as PNG and release it."""
    from smdcli.io_hdf5 import atomic_path

    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
