"""A parameter's model derivative again on a finer step: where the step of its stencil moves a piecewise-linear
scene's start across the edge between two branches of an element (two masses' equal starting speeds under a contact
between them, a speed's stencil 1e-3 wide), the start is on that edge only if a step near the parameter's rounding
still crosses it (event_sensitivity.py asks).

Must not import: io, plots, commands, cli.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from smdcli.analysis.model_derivative import (Derivative, _model_arrays, _rounding, _same_structure, _scene_at,
                                              stencil_weights)
from smdcli.analysis.signal_derivative import combined
from smdcli.errors import ScenarioError

FINER = (1e-3, 1e-6)  # the steps tried, as shares of the stencil's own: from 1e-2 of |p| down to 1e-8 of it


def finer(d: Derivative, share: float) -> Derivative | None:
    """d on a step `share` of its own, the same offsets (its models built again there, its error the rounding's
    at that step where that is larger); None where a point of it is no scene, or d keeps nothing to build from."""
    if not d.built_from:
        return None
    sc, doc, base, grid, structure, flowed = d.built_from
    delta = d.delta * share
    try:
        models = [base if o == 0 else _scene_at(sc, doc, base, d.path, d.value + o * delta) for o in d.offsets]
    except ScenarioError:
        return None
    for m in models:
        _same_structure(m, base, structure, grid, d.path)
    weights = stencil_weights(d.offsets) / delta
    arrays = [_model_arrays(m, float(grid[-1]), flowed) for m in models]
    largest = max((float(np.abs(a).max(initial=0.0)) for a in
                   (combined(weights, parts) for parts in zip(*arrays))), default=0.0)
    error = max(d.error, _rounding(arrays, weights, largest)) if largest > 0 else d.error
    return dataclasses.replace(d, delta=delta, models=models, weights=weights, error=error)
