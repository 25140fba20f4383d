"""Which class reads and runs each force shape, by the scenario's `type`.

Must not import: scenario, model, solvers, kernels, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from smdcli.shapes.base import Signal
from smdcli.shapes.chirp import Chirp
from smdcli.shapes.constant import Constant
from smdcli.shapes.expression import ExpressionSignal
from smdcli.shapes.fourier_square import FourierSquare
from smdcli.shapes.harmonic import Harmonic
from smdcli.shapes.pulse import Pulse
from smdcli.shapes.square import Square
from smdcli.shapes.step import Step
from smdcli.shapes.table import Table

_CLASSES = (Constant, Step, Harmonic, Square, FourierSquare, Pulse, Chirp, Table, ExpressionSignal)
# Force shapes by `type`, in the order the docs list them.
SHAPES: dict[str, type[Signal]] = {name: cls for cls in _CLASSES for name in cls.types}
FORCE_TYPES = tuple(SHAPES)
_KINDS = [kind for cls in _CLASSES for kind in cls.kinds]
assert len(set(_KINDS)) == len(_KINDS), "two force shapes share a compiled row kind"


def build_signal(spec) -> Signal:
    """The Signal a validated ForceSpec describes."""
    return SHAPES[spec.type].from_spec(spec)
