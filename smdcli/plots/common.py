"""What every figure shares: a Figure without pyplot, thinning of long series, atomic saving.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _figure(**kwargs):
    """A Figure on the Agg canvas, without pyplot's global state (and its import cost)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


_SUPERSCRIPT = str.maketrans("-−0123456789", "⁻⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def plain_log_labels(axis) -> None:
    """A log axis labelled 10⁻¹⁶, 6×10⁻¹⁶ in plain text: matplotlib's labels are mathtext, whose parser costs a
    fifth of a second of a run's plots the first time a figure draws them."""
    import re

    from matplotlib.ticker import LogFormatterSciNotation

    class Plain(LogFormatterSciNotation):
        def __call__(self, x, pos=None):
            text = super().__call__(x, pos)
            math = re.fullmatch(r"\$\\mathdefault\{(.*)\}\$", text)
            if math is None:
                return text
            body = math.group(1).replace("\\times", "×")
            return re.sub(r"\^\{([^}]*)\}", lambda power: power.group(1).translate(_SUPERSCRIPT), body)

    axis.set_major_formatter(Plain())
    axis.set_minor_formatter(Plain(labelOnlyBase=False))  # as a log scale's own minor labels


def legend_beside(fig, ax, **kwargs):
    """A legend to the right of the axes, the axes' right edge moved so that the legend ends inside the figure
    however long its labels (a fixed margin cut long ones off, and left short ones a third of the width)."""
    legend = ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), **kwargs)
    width = legend.get_window_extent(fig.canvas.get_renderer()).width / fig.bbox.width
    left = ax.get_position().x0
    fig.subplots_adjust(right=min(0.97, (0.98 - width + 0.01 * left) / 1.01))
    return legend


MAX_DRAWN = 2000  # points per line: about two per pixel column of the axes
MAX_DOFS_DRAWN = 10  # lines per axes that a reader can still tell apart (one per colour of the cycle)


def drawn_dofs(n: int, moving: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """The DOFs a figure draws, and a note for its title: all up to MAX_DOFS_DRAWN, else that many evenly spaced
    from the first to the last (a 10,000-mass chain's 10,000 lines are one blot, and minutes of drawing), among the
    `moving` ones where given (result.moving_columns: a wave's chain leaves most masses at 0, nine lines of ten
    flat)."""
    if n <= MAX_DOFS_DRAWN:
        return np.arange(n), ""
    among = np.arange(n) if moving is None else np.asarray(moving)
    picked = among[np.unique(np.linspace(0, len(among) - 1, MAX_DOFS_DRAWN).round().astype(int))] if len(among) \
        else among
    which = "" if moving is None else f" among the {len(among)} that move (the rest stay at 0)"
    return picked, f" ({len(picked)} of {n} DOFs drawn, evenly spaced{which}; the HDF5 file holds every one)"


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


def _wrap(text: str, width: int) -> str:
    """Break a long label or title line at spaces, keeping existing line breaks."""
    import textwrap

    return "\n".join(textwrap.fill(line, width) for line in text.split("\n"))


def save_figure(fig, path: Path) -> None:
    """Save a figure atomically as PNG and release it."""
    from smdcli.io.atomic import atomic_path

    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
