"""`type = "expression"`: a formula in t. No exact generator: the exact solver samples it.

Must not import: scenario, model, kernels, solvers, or any layer above.
"""

from __future__ import annotations

import numpy as np

from smdcli.shapes.base import Signal

EXPRESSION = 10  # compiled row kind


class ExpressionSignal(Signal):
    """A parsed expression in t; it jumps or kinks where an argument of sign, heaviside or abs crosses zero."""

    types = ("expression",)
    fields = ("expr",)
    kinds = (EXPRESSION,)
    exact = False
    series = False

    def __init__(self, text: str):
        from smdcli.expression import Expression

        self.expression = Expression(text)

    @classmethod
    def read(cls, t):
        from smdcli.expression import Expression, ExpressionError

        text = t.string("expr")
        try:
            Expression(text)
        except ExpressionError as exc:
            raise t.fail("expr", str(exc)) from None
        return {"expr": text}

    @classmethod
    def from_spec(cls, spec):
        return cls(spec.expr)

    def value(self, t):
        return self.expression(t)

    def value_left(self, t):
        # an edge is the first float past the crossing (Expression.edges): the float before it is on the near side;
        # where that float is outside the expression's domain (sqrt(t) at t = 0) the value at t is the limit
        before = self.expression(np.nextafter(t, -np.inf))
        outside = ~np.isfinite(before)
        return np.where(outside, self.expression(t), before) if outside.any() else before

    def breakpoints(self, t0, t1):
        return self.expression.edges(t0, t1)

    def edge_count(self, t0, t1, limit=None):
        from smdcli.expression import TooManyEdges

        try:
            return len(self.expression.edges(t0, t1, limit))
        except TooManyEdges as exc:
            return exc.count

    def derivative(self, start):
        derived = ExpressionSignal.__new__(ExpressionSignal)
        derived.expression = self.expression.derivative()
        return derived

    def kernel_row(self):
        codes, constants, depth = self.expression.program()
        return EXPRESSION, [float(depth)], constants, codes
