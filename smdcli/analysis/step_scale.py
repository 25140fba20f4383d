"""The scale a parameter's stencil steps are taken in, where |p| is too small for the model's numbers to move by it.

A step of 1e-2 of a Rayleigh beta of 1e-100 beside alpha M moves C by 1e-102 K, lost in C's rounding: the moved
model's numbers equal the scene's, and their difference said the derivative was zero, stated exact.

Imports nothing of smd.
"""

from __future__ import annotations

import math

import numpy as np

# below it a parameter is scaled as zero is: a step relative to 5e-324 (a Rayleigh beta hypothesis drew) is no
# number, and one relative to 1e-308 moves the model by subnormals (its difference divided by zero, or the flows
# of an infinite matrix); steps of 1e-7 of this are normal numbers still
SMALLEST_SCALE = math.sqrt(np.finfo(float).tiny)
# a step is widened where it moved the model's numbers by less than this share of themselves: most of its digits
# lost to their rounding (a law's k, partly in K as its hardening, moves K by 2.5e-4 of itself: its own)
LOST = 1e-6
WIDEST_STEP = 1e-2  # where a step moved none of the numbers built again for it: one of this (in p's units)


def wider_scale(before: list[np.ndarray], after: list[np.ndarray], delta: float, share: float = 1e-2) -> float:
    """The scale whose steps of `share` of it move the model's most moved array by `share` of itself, where the step
    delta moved every array it moved by less than LOST of itself (a Rayleigh beta of 1e-12 beside alpha M), or
    moved none of those built again for it (beta = 1e-100: the scale WIDEST_STEP / share); else 0. before, after:
    the model's arrays at p and p + delta (an array kept as it was is the same object: a law's own number, a yield
    force, builds none again)."""
    rebuilt = [(float(np.abs(b - a).max(initial=0.0)), float(np.abs(a).max(initial=0.0)))
               for a, b in zip(before, after) if a is not b and a.shape == b.shape]
    if any(move > 0 and held == 0 for move, held in rebuilt):
        return 0.0  # an array that was zero moved by the whole step (a belt's speed from 0, widened: 5 % off)
    moved = [(move, held) for move, held in rebuilt if move > 0 and held > 0]
    if not moved:
        return WIDEST_STEP / share if any(held > 0 for _, held in rebuilt) else 0.0
    move, held = max(moved, key=lambda pair: pair[0] / pair[1])
    return held * abs(delta) / move if move < LOST * held else 0.0


def relative_size(value: float) -> float:
    """|p|, or 1 at p = 0 and below SMALLEST_SCALE: the scale a sensitivity is normalized by (p dx/dp) and its
    stencil's steps are taken in."""
    return abs(value) if SMALLEST_SCALE <= abs(value) < math.inf else 1.0


def block_scales(derivatives) -> np.ndarray:
    """What each parameter's sensitivity block is scaled by (model_derivative's Derivatives): the scale its steps
    were taken in (a Rayleigh beta of 1e-100, stepped in a scale of 1, carries 1 dx/dbeta, not 1e-100 dx/dbeta far
    below the rounding of the response beside it)."""
    return np.array([d.scale or relative_size(d.value) for d in derivatives])
