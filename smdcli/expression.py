"""Force expressions in t: parsed into a whitelisted tree and interpreted, never eval'd.

Grammar: numbers, t, pi, e, + - * / **, unary minus, parentheses and calls of
sin cos tan exp log sqrt abs sign tanh heaviside with one argument.
Python's ``ast`` module only parses the text; every node kind outside the
whitelist is refused, so attribute access, subscripts, lambdas,
comprehensions, names other than t/pi/e and any other call cannot run.

Imports nothing of smd (the bottom layer).
"""

from __future__ import annotations

import ast
import math
from typing import Callable

import numpy as np

MAX_LENGTH = 2000
MAX_NODES = 500


def _heaviside(x):
    return np.where(x >= 0, 1.0, 0.0)


FUNCTIONS: dict[str, Callable] = {
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "exp": np.exp,
    "log": np.log,
    "sqrt": np.sqrt,
    "abs": np.abs,
    "sign": np.sign,
    "tanh": np.tanh,
    "heaviside": _heaviside,
}
CONSTANTS = {"pi": math.pi, "e": math.e}
_BINARY = {
    ast.Add: np.add,
    ast.Sub: np.subtract,
    ast.Mult: np.multiply,
    ast.Div: np.divide,
    ast.Pow: np.power,
}


class ExpressionError(ValueError):
    """The expression text is not in the grammar; the message says what was found."""


def _describe(node: ast.AST) -> str:
    names = {
        ast.Attribute: "attribute access",
        ast.Subscript: "subscripts",
        ast.Lambda: "lambda",
        ast.ListComp: "comprehensions",
        ast.GeneratorExp: "comprehensions",
        ast.SetComp: "comprehensions",
        ast.DictComp: "comprehensions",
        ast.Compare: "comparisons",
        ast.BoolOp: "boolean operators",
        ast.IfExp: "conditional expressions",
        ast.NamedExpr: "assignment",
        ast.Starred: "starred arguments",
    }
    return names.get(type(node), type(node).__name__)


def _check(node: ast.AST) -> None:
    if isinstance(node, ast.Expression):
        _check(node.body)
    elif isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(f"only real numbers are allowed, found {node.value!r}")
    elif isinstance(node, ast.Name):
        if node.id != "t" and node.id not in CONSTANTS:
            raise ExpressionError(
                f"unknown name {node.id!r}; allowed: t, pi, e and the functions "
                + ", ".join(FUNCTIONS)
            )
    elif isinstance(node, ast.BinOp):
        if type(node.op) not in _BINARY:
            raise ExpressionError(f"operator {type(node.op).__name__} is not allowed")
        _check(node.left)
        _check(node.right)
    elif isinstance(node, ast.UnaryOp):
        if not isinstance(node.op, (ast.USub, ast.UAdd)):
            raise ExpressionError(f"operator {type(node.op).__name__} is not allowed")
        _check(node.operand)
    elif isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name):
            raise ExpressionError(f"{_describe(node.func)} is not allowed")
        if node.func.id not in FUNCTIONS:
            what = node.func.id
            raise ExpressionError(
                f"call of {what!r} is not allowed; allowed functions: " + ", ".join(FUNCTIONS)
            )
        if node.keywords or len(node.args) != 1:
            raise ExpressionError(f"{node.func.id}() takes exactly one argument")
        _check(node.args[0])
    else:
        raise ExpressionError(f"{_describe(node)} is not allowed")


def _interpret(node: ast.AST, t: np.ndarray):
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return t if node.id == "t" else CONSTANTS[node.id]
    if isinstance(node, ast.BinOp):
        return _BINARY[type(node.op)](_interpret(node.left, t), _interpret(node.right, t))
    if isinstance(node, ast.UnaryOp):
        value = _interpret(node.operand, t)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Call):
        return FUNCTIONS[node.func.id](_interpret(node.args[0], t))
    raise AssertionError("unchecked node")  # _check guarantees this is unreachable


class Expression:
    """A checked expression in t that evaluates on float arrays."""

    def __init__(self, text: str):
        if not isinstance(text, str) or not text.strip():
            raise ExpressionError("expected a non-empty expression in t")
        if len(text) > MAX_LENGTH:
            raise ExpressionError(f"expression is {len(text)} characters long; the limit is {MAX_LENGTH}")
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except (SyntaxError, ValueError, RecursionError, MemoryError) as exc:
            raise ExpressionError(f"cannot parse expression: {getattr(exc, 'msg', exc)}") from None
        if sum(1 for _ in ast.walk(tree)) > MAX_NODES:
            raise ExpressionError(f"expression has more than {MAX_NODES} terms")
        _check(tree)
        self.text = text
        self._body = tree.body

    def __call__(self, t):
        """Evaluate at t (scalar or array); float64 result of t's shape."""
        t_arr = np.asarray(t, dtype=float)
        with np.errstate(all="ignore"):
            value = _interpret(self._body, t_arr)
        return np.broadcast_to(np.asarray(value, dtype=float), t_arr.shape).copy()
