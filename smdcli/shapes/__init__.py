"""Force shapes: one module each, registered in registry.py (see base.py for what a shape answers).

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from smdcli.shapes.base import EDGE_SNAP, Exo, Signal
from smdcli.shapes.registry import FORCE_TYPES, SHAPES, build_signal

__all__ = ["EDGE_SNAP", "Exo", "FORCE_TYPES", "SHAPES", "Signal", "build_signal"]
