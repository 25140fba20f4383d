"""The start-up baseline for a run with plots: import matplotlib and save one three-panel figure of 1,001 points,
as a user's script would (Agg, a Figure without pyplot). `python benchmarks/one_figure.py FOLDER`."""

import sys

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

t = np.linspace(0.0, 10.0, 1001)
figure = Figure(figsize=(8, 8))
FigureCanvasAgg(figure)
for i, axes in enumerate(figure.subplots(3, 1, sharex=True)):
    axes.plot(t, np.sin((i + 1) * t))
    axes.set_ylabel(f"x{i + 1} [m]")
axes.set_xlabel("time [s]")
figure.savefig(f"{sys.argv[1]}/figure.png", dpi=100)
