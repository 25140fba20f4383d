"""Figures from Results. Plot functions return a Figure; only save_figure touches disk."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from smdcli.result import Result


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _title(title: str, result: Result) -> str:
    return f"{title}\n{result.stats.method}: {result.stats.reason}" if len(result.stats.reason) < 90 else \
        f"{title}\n{result.stats.method}"


def response_figure(result: Result, title: str):
    """Displacement, velocity and acceleration against time, one line per DOF; force on a second axis."""
    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(9, 8.5), sharex=True, constrained_layout=True)
    quantities = (("displacement", "Displacement x [m]"), ("velocity", "Velocity v [m/s]"),
                  ("acceleration", "Acceleration a [m/s²]"))
    for ax, (name, label) in zip(axes, quantities):
        data = getattr(result, name)
        for j, dof in enumerate(result.dofs):
            ax.plot(result.time, data[:, j], lw=1.1, label=dof, color=f"C{j}")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.4)
    forced = np.any(result.force != 0)
    if forced:
        twin = axes[0].twinx()
        for j, dof in enumerate(result.dofs):
            if np.any(result.force[:, j] != 0):
                twin.plot(result.time, result.force[:, j], lw=0.8, ls="--", color=f"C{j}", alpha=0.55,
                          label=f"F on {dof}")
        twin.set_ylabel("Applied force F [N] (dashed)")
        lines = axes[0].get_lines() + twin.get_lines()
        axes[0].legend(lines, [ln.get_label() for ln in lines], loc="upper right", fontsize=8, ncol=2)
    else:
        axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("Time t [s]")
    axes[0].set_xlim(result.time[0], result.time[-1])
    fig.suptitle(_title(title, result), fontsize=10)
    return fig


def phase_figure(result: Result, title: str):
    """Phase portrait: velocity against displacement per DOF, start marked."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 6), constrained_layout=True)
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

    plt = _pyplot()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
