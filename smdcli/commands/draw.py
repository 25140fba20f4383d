"""`smd draw` and `smd animate`: the schematic as a PNG, and a GIF of the masses moving, time-stamped.

Must not import: cli."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from smdcli.errors import UsageError
from smdcli.io.atomic import atomic_path
from smdcli.io.folders import output_folder
from smdcli.model import build
from smdcli.plots.common import _figure, save_figure
from smdcli.plots.schematic import SPACING, draw, layout, schematic_figure
from smdcli.progress import bar
from smdcli.scenario import TimeSpec
from smdcli.solvers.run import load as load_checked, solve_checked


def write_schematic(path: str | Path, out: str | Path) -> Path:
    """`smd draw`: OUT/<stem>_schematic.png."""
    sc = load_checked(path)
    build(sc)
    out_dir = output_folder(out)
    png = out_dir / f"{sc.stem}_schematic.png"
    save_figure(schematic_figure(sc), png)
    return png


def animate(path: str | Path, out: str | Path, fps: int = 20, seconds: float | None = None,
            scale: float | None = None, start: float | None = None, end: float | None = None,
            method: str | None = None, progress: bool = False) -> tuple[Path, dict]:
    """`smd animate`: OUT/<stem>.gif of the masses moving, displacements scaled to be seen, time stamped."""
    if not 1 <= fps <= 50:
        raise UsageError(f"--fps: expected 1 to 50 frames per second, found {fps}")
    sc = load_checked(path)
    t0 = sc.time.start if start is None else start
    t1 = sc.time.end if end is None else end
    if not sc.time.start <= t0 < t1 <= sc.time.end:
        raise UsageError(f"--start/--end: expected {sc.time.start:g} <= start < end <= {sc.time.end:g}, "
                         f"found {t0:g} and {t1:g}")
    length = min(t1 - t0, 20.0) if seconds is None else seconds
    if not 0 < length <= 60:
        raise UsageError(f"--seconds: expected a GIF length in (0, 60] s, found {length:g}")
    frames = max(2, int(round(length * fps)))
    # The whole run from the scenario's start (the state at t0 depends on it), sampled at the frames.
    lead = t0 - sc.time.start
    step = (t1 - t0) / (frames - 1)
    skip = int(round(lead / step)) if lead > 0 else 0
    grid = TimeSpec(sc.time.start, sc.time.start + (skip + frames - 1) * step, points=skip + frames)
    out_dir = output_folder(out)
    result = solve_checked(dataclasses.replace(sc, time=grid), method)
    t, x = result.time[skip:], result.displacement[skip:]
    # Under support motion the masses are drawn where they are (absolute) and the walls move with the ground.
    ground = np.zeros(len(t)) if result.ground is None else result.ground.displacement[skip:]
    if result.ground is not None:
        x = result.absolute("displacement")[skip:]
    peak = max(np.abs(x).max(), np.abs(ground).max())
    if scale is None:
        scale = 0.3 * SPACING / peak if peak > 0 else 1.0
    plan = layout(sc)
    n = len(plan.names)
    fig = _figure(figsize=(1.6 + 1.9 * n, 2.2), dpi=80)
    ax = fig.add_axes((0.0, 0.0, 1.0, 0.86))
    images, palette = [], None
    from PIL import Image

    with bar("drawing frames", len(t), progress) as advance:
        for k in range(len(t)):
            for artist in [*ax.lines, *ax.patches, *ax.texts, *ax.collections, *ax.images, *ax.artists]:
                artist.remove()  # not ax.clear(), which rebuilds the hidden axes' ticks: a third of a frame's time
            draw(ax, plan, x[k], scale, labels=False, ground=ground[k])
            fig.texts.clear()
            fig.text(0.02, 0.93, f"t = {t[k]:7.2f} s", fontsize=9, family="monospace")
            fig.text(0.98, 0.93, f"displacements x {scale:.3g}", fontsize=8, ha="right", color="0.35")
            fig.canvas.draw()
            rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3]
            if palette is None:  # the first frame's 32 colours for every frame: the same artists move
                palette = _Palette(Image.fromarray(rgb).quantize(colors=32, method=Image.Quantize.MEDIANCUT,
                                                                 dither=Image.Dither.NONE))
            images.append(palette.image(rgb))
            advance(1)
    gif = out_dir / f"{sc.stem}.gif"
    with atomic_path(gif) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps),
                       loop=0, optimize=True, disposal=1)
    size = gif.stat().st_size
    return gif, {"frames": len(images), "fps": fps, "scale": scale, "bytes": size, "start": float(t[0]),
                 "end": float(t[-1])}


class _Palette:
    """A frame's colours mapped to a palette's nearest, exactly, each colour looked up once (PIL's own mapping
    reads a white background as 252, 252, 252) and remembered: a frame in a fifth of a millisecond where choosing
    its own 32 colours took 7 ms."""

    def __init__(self, first):
        self.colors = np.array(first.getpalette()[:96], dtype=float).reshape(-1, 3)
        self.palette = self.colors.astype(np.uint8).ravel().tolist()  # as putpalette takes it
        self.index = np.full(1 << 24, 255, dtype=np.uint8)  # 24-bit colour -> palette index; 255: not met yet

    def image(self, rgb: np.ndarray):
        """The (h, w, 3) frame as a paletted image."""
        from PIL import Image

        codes = (rgb[..., 0].astype(np.uint32) << 16) | (rgb[..., 1].astype(np.uint32) << 8) | rgb[..., 2]
        found = self.index[codes]
        new = np.unique(codes[found == 255])
        if len(new):
            colors = np.stack([new >> 16, (new >> 8) & 255, new & 255], axis=1).astype(float)
            self.index[new] = ((colors[:, None, :] - self.colors[None]) ** 2).sum(axis=2).argmin(axis=1)
            found = self.index[codes]
        image = Image.fromarray(found, mode="P")
        image.putpalette(self.palette)
        return image
