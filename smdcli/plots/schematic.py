"""The system drawn from its elements: masses in a row in DOF order, a ground element tied to the nearer
wall, elements between the same two nodes in lanes, elements that skip a mass arced over the row. A
matrix-form scene's elements are read back from M, C, K (off-diagonal -K_ij between i and j, row sums to
the ground).

Plot functions return a Figure; only save_figure touches disk. Must not import: commands, cli."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from smdcli.plots.common import _figure, _wrap
from smdcli.scenario import GROUND, Scenario

SPACING = 1.0  # between mass centres at rest
BLOCK = 0.34  # block width and height
WALL_GAP = 0.9  # wall to the nearest mass centre
UNITS = {"k": "N/m", "c": "N s/m"}
@dataclass(frozen=True)
class Element:
    """A spring, damper, friction contact or stop between two nodes (a DOF index or "left"/"right" wall),
    labelled."""

    kind: str  # "spring" | "damper" | "friction" | "stop"
    a: int | str
    b: int | str
    label: str
    nonlinear: bool = False


@dataclass(frozen=True)
class Layout:
    """Where everything is drawn at rest."""

    names: tuple[str, ...]
    masses: tuple[float, ...]
    elements: tuple[Element, ...]
    forces: tuple[tuple[int, str], ...]  # (DOF, label)
    left_wall: bool
    right_wall: bool


def _wall(i: int, n: int) -> str:
    return "left" if i <= (n - 1) / 2 else "right"


def layout(sc: Scenario) -> Layout:
    """The drawing's elements, from the scenario's element list or read back from its matrices."""
    names = sc.dof_names
    n = len(names)
    index = {name: i for i, name in enumerate(names)}
    elements = []
    if sc.system is None:
        masses = tuple(m.m for m in sc.masses)
        for e in sc.springs + sc.dampers + sc.frictions + sc.stops:
            ends = [index[node] if node != GROUND else None for node in e.connects]
            if None in ends:
                i = ends[0] if ends[0] is not None else ends[1]
                a, b = (_wall(i, n), i) if _wall(i, n) == "left" else (i, _wall(i, n))
            else:
                a, b = sorted(ends)
            if e.kind in ("friction", "stop"):
                elements.append(Element(e.kind, a, b, _contact_label(e), True))
                continue
            symbol = "k" if e.kind == "spring" else "c"
            units = "N/m" if e.kind == "spring" else "N s²/m²" if e.law == "quadratic" else "N s/m"
            label = f"{symbol}{e.index + 1} = {e.coef:g} {units}"
            if e.law == "cubic":
                label += f", k3 = {e.k3:g} N/m³"
            elif e.law not in ("linear", "quadratic"):
                label += f" ({e.law.replace('_', '-')})"
            elif e.law == "quadratic":
                label += " (quadratic)"
            elements.append(Element(e.kind, a, b, label, e.law != "linear"))
    else:
        M, C, K = sc.system.dense()
        masses = tuple(np.diag(M))
        for kind, matrix, symbol in (("spring", K, "k"), ("damper", C, "c")):
            for i in range(n):
                for j in range(i + 1, n):
                    if matrix[i, j] != 0:
                        elements.append(Element(kind, i, j, f"{symbol} = {-matrix[i, j]:g} {UNITS[symbol]}"))
                to_ground = matrix[i].sum()
                if abs(to_ground) > 1e-12 * max(np.abs(matrix).max(), 1.0):
                    wall = _wall(i, n)
                    a, b = (wall, i) if wall == "left" else (i, wall)
                    elements.append(Element(kind, a, b, f"{symbol} = {to_ground:g} {UNITS[symbol]}"))
    forces = tuple((index[f.on], _force_label(f)) for f in sc.forces)
    walls = {e.a for e in elements} | {e.b for e in elements}
    return Layout(names, masses, tuple(elements), forces, "left" in walls, "right" in walls)


def _contact_label(e) -> str:
    """A friction contact's or a stop's label: what its law holds."""
    law = e.nonsmooth
    if e.kind == "friction":
        parts = [f"F = {law.force:g} N"]
        if law.static is not None and law.static != law.force:
            parts.append(f"static {law.static:g} N")
        if law.belt_velocity:
            parts.append(f"belt {law.belt_velocity:g} m/s")
        lines = [f"friction{e.index + 1}"]
        for part in parts:  # lines short enough for the gap between a wall and a mass
            if len(lines) > 1 and len(lines[-1]) + len(part) <= 20:
                lines[-1] += f", {part}"
            else:
                lines.append(part)
        return "\n".join(lines)
    limits = ", ".join(f"{side} {value:g} m" for side, value in (("min", law.min), ("max", law.max))
                       if value is not None)
    return f"stop{e.index + 1}, {law.contact}\n{limits}"


class _Pen:
    """The drawing's lines, added as one LineCollection per style (colour, width, zorder) by finish(): an animation
    frame's forty lines as a few artists (a Line2D each took a millisecond to make and another to draw)."""

    def __init__(self, ax):
        self.ax, self.strokes = ax, {}

    def line(self, xs, ys, color, width: float, zorder: float = 2.0) -> None:
        """A polyline through (xs, ys), drawn as a plot line of that colour and width."""
        self.strokes.setdefault((color, width, zorder), []).append(np.column_stack([xs, ys]))

    def finish(self) -> None:
        """Add the lines to the axes (their ends and joins as a plot line's: projecting caps, round joins)."""
        from matplotlib.collections import LineCollection

        for (color, width, zorder), paths in self.strokes.items():
            self.ax.add_collection(LineCollection(paths, colors=color, linewidths=width, zorder=zorder,
                                                  capstyle="projecting", joinstyle="round"), autolim=False)
        self.strokes = {}


def _friction_pad(pen, x0: float, x1: float, y: float, color) -> None:
    """A friction contact: a shoe pressed on a hatched sliding surface."""
    from matplotlib.patches import Rectangle

    mid = 0.5 * (x0 + x1)
    width = min(0.2, 0.5 * (x1 - x0))
    h = 0.035
    pen.line([x0, mid - width / 2], [y, y], color, 1.4)
    pen.ax.add_patch(Rectangle((mid - width / 2, y - h), width, 2 * h, facecolor="white", edgecolor=color,
                               lw=1.4, hatch="////", zorder=2))
    pen.line([mid - width / 2 - 0.03, mid + width / 2 + 0.03], [y - h - 0.012] * 2, color, 2.0)
    pen.line([mid + width / 2, x1], [y - h - 0.012, y - h - 0.012], color, 1.4)
    pen.line([x1, x1], [y - h - 0.012, y], color, 1.4)


def _stop_gap(pen, x0: float, x1: float, y: float, color) -> None:
    """A stop: two plates facing across the clearance."""
    mid = 0.5 * (x0 + x1)
    gap = min(0.08, 0.3 * (x1 - x0))
    h = 0.05
    pen.line([x0, mid - gap / 2], [y, y], color, 1.4)
    pen.line([mid - gap / 2] * 2, [y - h, y + h], color, 2.4)
    pen.line([mid + gap / 2] * 2, [y - h, y + h], color, 2.4)
    pen.line([mid + gap / 2, x1], [y, y], color, 1.4)


def _force_label(f) -> str:
    amplitude = f"{f.amplitude:g} N" if f.type not in ("table", "expression") else ""
    if f.type in ("sine", "cosine"):
        return f"F = {f.amplitude:g} {'sin' if f.type == 'sine' else 'cos'}({f.omega:g} t)"
    if f.type == "expression":
        return f"F = {f.expr}" if len(f.expr or "") < 28 else "F(t) expression"
    return f"F: {f.type.replace('_', ' ')} {amplitude}".strip()


def _node_x(node: int | str, positions: np.ndarray, wall_shift: float = 0.0) -> float:
    if node == "left":
        return -WALL_GAP + wall_shift
    if node == "right":
        return (len(positions) - 1) * SPACING + WALL_GAP + wall_shift
    return positions[node]


def _zigzag(x0: float, x1: float, y: float, turns: int = 6, height: float = 0.045):
    """A spring's line: straight ends and a zigzag between."""
    length = x1 - x0
    lead = 0.15 * length
    xs = np.linspace(x0 + lead, x1 - lead, 2 * turns + 1)
    ys = np.full_like(xs, y)
    ys[1:-1:2] += height
    ys[2:-1:2] -= height
    return np.concatenate([[x0], xs, [x1]]), np.concatenate([[y], ys, [y]])


def _dashpot(pen, x0: float, x1: float, y: float, color) -> None:
    """A damper: rod, open cylinder and piston."""
    mid = 0.5 * (x0 + x1)
    width = min(0.18, 0.45 * (x1 - x0))
    h = 0.04
    pen.line([x0, mid - width / 2], [y, y], color, 1.4)
    pen.line([mid - width / 2, mid + width / 2, mid + width / 2, mid - width / 2],
             [y + h, y + h, y - h, y - h], color, 1.4)
    piston = mid
    pen.line([piston, piston], [y - 0.8 * h, y + 0.8 * h], color, 2.2)
    pen.line([piston, x1], [y, y], color, 1.4)


def draw(ax, plan: Layout, displacement: np.ndarray | None = None, scale: float = 1.0, labels: bool = True,
         ground: float = 0.0) -> None:
    """Draw the system on an axes, masses moved by scale * displacement (absolute) and the walls by scale * ground
    (a support that moves)."""
    from matplotlib.patches import Rectangle

    n = len(plan.names)
    rest = np.arange(n) * SPACING
    positions = rest + (scale * np.asarray(displacement) if displacement is not None else 0.0)
    half = BLOCK / 2
    ax.set_xlim(-WALL_GAP - 0.35, (n - 1) * SPACING + WALL_GAP + 0.35)
    ax.set_ylim(-0.75, 0.75)
    ax.set_aspect("equal")
    ax.axis("off")
    pen = _Pen(ax)
    shift = scale * ground
    for wall, x in (("left", -WALL_GAP + shift), ("right", (n - 1) * SPACING + WALL_GAP + shift)):
        if getattr(plan, f"{wall}_wall"):
            pen.line([x, x], [-0.42, 0.42], "k", 2.5)
            sign = -1 if wall == "left" else 1
            for y in np.linspace(-0.4, 0.4, 9):
                pen.line([x, x + sign * 0.07], [y, y + 0.05], "k", 0.8)
    pen.line([-WALL_GAP, (n - 1) * SPACING + WALL_GAP], [-half - 0.02] * 2, "0.75", 0.8, zorder=0)
    # Lanes: elements sharing a gap are spread above and below the centre line.
    lanes: dict[tuple, int] = {}
    offsets = (0.09, -0.09, 0.0, 0.15, -0.15)
    for e in plan.elements:
        key = (e.a, e.b)
        lane = lanes.get(key, 0)
        lanes[key] = lane + 1
        skips = isinstance(e.a, int) and isinstance(e.b, int) and abs(e.b - e.a) > 1
        x0 = _node_x(e.a, positions, shift) + (half if isinstance(e.a, int) else 0.0)
        x1 = _node_x(e.b, positions, shift) - (half if isinstance(e.b, int) else 0.0)
        color = "tab:red" if e.nonlinear else "k"
        y = 0.3 + 0.1 * lane if skips else offsets[lane % len(offsets)]
        if skips:  # over the masses in between: rise from the blocks' tops
            x0, x1 = _node_x(e.a, positions), _node_x(e.b, positions)
            pen.line([x0, x0], [half, y], color, 1.0)
            pen.line([x1, x1], [half, y], color, 1.0)
        if e.kind == "spring":
            xs, ys = _zigzag(x0, x1, y)
            pen.line(xs, ys, color, 1.4)
        elif e.kind == "friction":
            _friction_pad(pen, x0, x1, y, color)
        elif e.kind == "stop":
            _stop_gap(pen, x0, x1, y, color)
        else:
            _dashpot(pen, x0, x1, y, color)
        if labels:  # below the row, a lower lane's label is under the floor line, not across it
            ax.text(0.5 * (x0 + x1), y + 0.06 if y >= 0 else -half - 0.05, e.label, ha="center",
                    va="bottom" if y >= 0 else "top", fontsize=7 if len(e.label) <= 30 else 6, color=color,
                    linespacing=1.1)
    pen.finish()
    for i, x in enumerate(positions):
        ax.add_patch(Rectangle((x - half, -half), BLOCK, BLOCK, facecolor="#9ecae1", edgecolor="k", lw=1.3, zorder=3))
        text = plan.names[i] + (f"\n{plan.masses[i]:g} kg" if labels else "")
        ax.text(x, 0, text, ha="center", va="center", fontsize=8, zorder=4)
    for dof, label in plan.forces:
        x = positions[dof]
        ax.annotate("", xy=(x + 0.28, half + 0.2), xytext=(x - 0.05, half + 0.2),
                    arrowprops={"arrowstyle": "-|>", "color": "tab:green", "lw": 1.8})
        if labels:
            ax.text(x + 0.12, half + 0.26, label, ha="center", va="bottom", fontsize=7, color="tab:green")


def schematic_figure(sc: Scenario):
    """The schematic of a scenario, labelled, as a Figure."""

    plan = layout(sc)
    n = len(plan.names)
    fig = _figure(figsize=(2.2 + 2.6 * n, 3.6))
    ax = fig.add_axes((0.01, 0.02, 0.98, 0.8))
    draw(ax, plan)
    legend = "red: nonlinear element" if any(e.nonlinear for e in plan.elements) else ""
    form = "element form" if sc.system is None else "matrix form (elements read back from K and C)"
    fig.suptitle(_wrap(f"{sc.title or sc.stem}\n{form}" + (f"; {legend}" if legend else ""), 70), fontsize=9)
    notes = []
    if sc.ground_motion is not None:  # the wall is the support that moves
        g = sc.ground_motion
        notes.append(f"the wall moves: [ground_motion] {g.quantity} ({g.shape.type}"
                     + (f", {Path(g.shape.file).name}" if g.shape.file else "") + ")")
    if sc.damping is not None:
        d = sc.damping
        notes.append("plus [damping]: " + (f"modal ratios {', '.join(f'{z:g}' for z in d.modal)}" if d.modal else
                                           f"Rayleigh C = {d.alpha:g} M + {d.beta:g} K"))
    if notes:
        fig.text(0.5, 0.03, "\n".join(notes), ha="center", va="bottom", fontsize=8, color="0.25")
    return fig
