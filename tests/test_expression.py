"""Expression forces: evaluated by a whitelisted interpreter, everything else refused."""

import math

import numpy as np
import pytest

from smdcli.expression import Expression, ExpressionError


def test_evaluates_the_grammar():
    t = np.linspace(0, 2, 9)
    e = Expression("20*sin(120*t) + 3*heaviside(t - 1) - e**(-t/2) * abs(cos(pi*t)) + sqrt(4) ** 2")
    expected = 20 * np.sin(120 * t) + 3 * (t >= 1) - math.e ** (-t / 2) * np.abs(np.cos(np.pi * t)) + 4.0
    np.testing.assert_allclose(e(t), expected, rtol=1e-15, atol=1e-13)
    assert Expression("-t")(2.0) == -2.0


@pytest.mark.parametrize("text, message", [
    ("__import__('os')", "call of '__import__'"),
    ("__import__('os').system('true')", "attribute access"),
    ("t.__class__", "attribute access"),
    ("sin.__globals__", "attribute access"),
    ("(lambda: 1)()", "lambda"),
    ("[x for x in (1, 2)]", "comprehensions"),
    ("foo(t)", "call of 'foo'"),
    ("x + 1", "unknown name 'x'"),
    ("open('/etc/passwd')", "call of 'open'"),
    ("sin(t, 2)", "exactly one argument"),
    ("t if t else 1", "conditional"),
    ("'abc'", "real numbers"),
    ("t[0]", "subscripts"),
    ("import os", "cannot parse"),
    ("t = 1", "cannot parse"),
    ("1 + " * 3000 + "1", "characters long"),
])
def test_refuses_anything_else(text, message):
    with pytest.raises(ExpressionError, match=message):
        Expression(text)


@pytest.mark.parametrize("text, span, expected", [
    ("heaviside(t - 1.013)", (0.0, 5.0), [1.013]),
    ("sign(sin(2*pi*t))", (0.0, 5.0), [0.5 * k for k in range(1, 10)]),
    ("abs(t - 2.5) + sin(3*t)", (0.0, 5.0), [2.5]),
    ("sign(cos(7*t)) + heaviside(t - 3)", (0.0, 10.0), sorted([3.0] + [(math.pi / 2 + k * math.pi) / 7 for k in range(23)
                                                               if (math.pi / 2 + k * math.pi) / 7 < 10])),
    ("heaviside(sin(2*pi*1000*t))", (0.0, 10.0), [k / 2000 for k in range(1, 20000)]),
    ("sin(t) + tanh(t - 1)", (0.0, 5.0), []),
    ("heaviside(t - 1)", (0.0, 1.0), []),  # an edge at the end of the span is not inside it
])
def test_edges_are_where_an_argument_of_sign_heaviside_or_abs_crosses_zero(text, span, expected):
    """Found to adjacent floats, a coarse sampling does not alias a fast square wave (20,000 edges), and each
    edge is the first float past its crossing: the float before it gives the left limit."""
    expression = Expression(text)
    edges = expression.edges(*span)
    assert len(edges) == len(expected)
    assert np.abs(edges - np.array(expected)).max(initial=0.0) <= 4e-15 * span[1]
    if "heaviside(t - 1.013)" in text:
        assert expression(np.nextafter(edges[0], -np.inf)) == 0.0 and expression(edges[0]) == 1.0
