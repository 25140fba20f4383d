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
