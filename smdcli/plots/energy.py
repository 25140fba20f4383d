"""The energy balance of a run: where the energy went, and how far the balance is from closing.

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

import numpy as np

from smdcli.plots.common import _figure, _wrap, envelope, plain_log_labels
from smdcli.result import Result


def energy_figure(result: Result, title: str):
    """Kinetic, strain, dissipated and input energy against time, and |residual| over the largest energy."""
    e = result.energy
    t = result.time
    fig = _figure(figsize=(9, 6.5))  # laid out from its titles' lines below: constrained layout drew it twice
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    stored = e.kinetic + e.strain + (e.contact if e.contact is not None else 0.0)
    curves = [("kinetic", e.kinetic, "-"), ("strain", e.strain, "-")]
    if e.contact is not None and np.any(e.contact):
        curves.append(("contact (stored)", e.contact, "-"))
    curves += [("kinetic + strain" + (" + contact" if e.contact is not None and np.any(e.contact) else ""), stored, "-"),
               ("dissipated (cumulative)", e.dissipated, "--"), ("input (cumulative)", e.input, "--")]
    for name in ("hysteretic", "friction", "impact"):
        data = getattr(e, name)
        if data is not None and np.any(data):
            curves.append((f"{name} (cumulative)", data, "-."))
    for name, data, style in curves:  # the sum wide and pale beneath: strain alone is often all of it
        wide = name.startswith("kinetic + ")
        top.plot(*envelope(t, data), style, lw=4.0 if wide else 1.0, alpha=0.35 if wide else 1.0,
                 zorder=1 if wide else 2, label=name)
    top.set_ylabel("energy [J]")
    top.legend(loc="best", fontsize=8)
    top.grid(alpha=0.3)
    heading = _wrap(f"{title}\nenergy balance ({result.stats.method})", 90)
    top.set_title(heading, fontsize=10)
    reached = e.largest
    relative = np.abs(e.residual) / reached if reached > 0 else np.zeros_like(e.residual)
    floor = np.finfo(float).eps  # an exact zero has no place on a log axis: drawn at machine epsilon
    bottom.semilogy(*envelope(t, np.maximum(relative, floor)), lw=1.0, color="C3")
    plain_log_labels(bottom.yaxis)
    bottom.axhline(e.max_relative_residual, color="0.4", lw=0.8, ls=":")
    bottom.set_ylabel("|residual| / largest energy")
    bottom.set_xlabel("time [s]")
    bottom.grid(alpha=0.3, which="both")
    # only the terms this scene has: a subtitle naming contact, friction and impact where there are none misreads
    losses = "".join(f" + {name}" for name in ("hysteretic", "friction", "impact")
                     if getattr(e, name) is not None and np.any(getattr(e, name)))
    contact = " + contact" if e.contact is not None and np.any(e.contact) else ""
    caption = _wrap(f"kinetic + strain{contact} - initial + dissipated{losses} - input: at most "
                    f"{e.max_relative_residual:.2g} of the largest energy ({e.quadrature})", 110)
    bottom.set_title(caption, fontsize=8)
    _leave_room(fig, heading.count("\n") + 1, caption.count("\n") + 1)
    return fig


def _leave_room(fig, heading_lines: int, caption_lines: int) -> None:
    """Margins for the two titles' lines (10 pt above the top axes, 8 pt between the axes), the tick labels and
    the axis labels, in points of the figure's height."""
    height = fig.get_figheight() * 72.0
    top = 1.0 - (heading_lines * 12.5 + 8.0) / height
    bottom = 42.0 / height
    gap = caption_lines * 10.0 + 10.0
    mean_axes = ((top - bottom) * height - gap) / 2.0
    fig.subplots_adjust(left=0.1, right=0.98, top=top, bottom=bottom, hspace=gap / mean_axes)
