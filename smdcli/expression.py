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
MAX_DEPTH = 64  # nesting of operations and calls, checked while parsing (before anything recurses)
MAX_PROGRAM = 20_000  # operations one evaluation runs, derivatives included (a ground displacement's second)


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
        try:
            value = float(node.value)
        except OverflowError:  # an integer literal of hundreds of digits
            raise ExpressionError(f"the number {_digits(node.value)} is too large for double precision") from None
        if not math.isfinite(value):
            raise ExpressionError("the number 1e309 or larger is too large for double precision; expected finite "
                                  "numbers")
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


def _digits(value: int) -> str:
    """An integer literal by its size (str() of a huge int is refused past 4300 digits)."""
    return f"of about {int(abs(value).bit_length() * 0.30103) + 1} digits"


def _depth(tree: ast.AST) -> int:
    """The nesting depth of a tree, without recursion (a deep tree must not exhaust Python's stack)."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return deepest


def _interpret(node: ast.AST, t: np.ndarray, memo: dict | None = None):
    """The value of a checked tree at t. A derivative shares subtrees (a DAG): memo evaluates each node once."""
    if memo is not None:
        key = id(node)
        if key in memo:
            return memo[key][1]
    if isinstance(node, ast.Constant):
        value = float(node.value)
    elif isinstance(node, ast.Name):
        value = t if node.id == "t" else CONSTANTS[node.id]
    elif isinstance(node, ast.BinOp):
        value = _BINARY[type(node.op)](_interpret(node.left, t, memo), _interpret(node.right, t, memo))
    elif isinstance(node, ast.UnaryOp):
        value = _interpret(node.operand, t, memo)
        value = -value if isinstance(node.op, ast.USub) else value
    elif isinstance(node, ast.Call):
        value = FUNCTIONS[node.func.id](_interpret(node.args[0], t, memo))
    else:
        raise AssertionError("unchecked node")  # _check guarantees this is unreachable
    if memo is not None:
        memo[id(node)] = (node, value)  # the node is kept so that its id is not reused while memo lives
    return value


def program_size(node: ast.AST) -> tuple[int, int]:
    """(operations, depth) of the postfix program of a tree whose subtrees may be shared, counted without
    expanding it: a derivative's program can be far larger than its tree."""
    sizes: dict[int, tuple[int, int]] = {}
    stack = [(node, False)]
    while stack:  # post-order without recursion, each shared subtree sized once
        n, expanded = stack.pop()
        if id(n) in sizes:
            continue
        children = _operands(n)
        if not expanded:
            stack.append((n, True))
            stack.extend((c, False) for c in children if id(c) not in sizes)
            continue
        counted = [sizes[id(c)] for c in children]
        sizes[id(n)] = (1 + sum(c[0] for c in counted), 1 + max((c[1] for c in counted), default=0))
    return sizes[id(node)]


def _operands(node: ast.AST) -> list[ast.AST]:
    if isinstance(node, ast.BinOp):
        return [node.left, node.right]
    if isinstance(node, ast.UnaryOp):
        return [node.operand]
    if isinstance(node, ast.Call):
        return [node.args[0]]
    return []


# Opcodes of the postfix program a compiled kernel runs (smdcli.kernels.forces): one per grammar element.
OP_CONST, OP_T, OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_POW, OP_NEG = range(8)
OP_FUNCTION = {name: 8 + i for i, name in enumerate(FUNCTIONS)}
_OP_BINARY = {ast.Add: OP_ADD, ast.Sub: OP_SUB, ast.Mult: OP_MUL, ast.Div: OP_DIV, ast.Pow: OP_POW}


def _postfix(node: ast.AST, codes: list[int], constants: list[float]) -> int:
    """Append node's program to codes (constants alongside); returns the stack depth it needs."""
    if isinstance(node, ast.Constant) or (isinstance(node, ast.Name) and node.id != "t"):
        codes.append(OP_CONST)
        constants.append(float(node.value) if isinstance(node, ast.Constant) else CONSTANTS[node.id])
        return 1
    if isinstance(node, ast.Name):
        codes.append(OP_T)
        return 1
    if isinstance(node, ast.BinOp):
        depth = max(_postfix(node.left, codes, constants), 1 + _postfix(node.right, codes, constants))
        codes.append(_OP_BINARY[type(node.op)])
        return depth
    if isinstance(node, ast.UnaryOp):
        depth = _postfix(node.operand, codes, constants)
        if isinstance(node.op, ast.USub):
            codes.append(OP_NEG)
        return depth
    if isinstance(node, ast.Call):
        depth = _postfix(node.args[0], codes, constants)
        codes.append(OP_FUNCTION[node.func.id])
        return depth
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
        # Python's tree is ~3 levels an operation deep (calls, names, contexts); it is measured without recursion
        # before anything recurses on it, the operations after the check
        if _depth(tree) > 4 * MAX_DEPTH:
            raise ExpressionError(f"expression is nested more than {MAX_DEPTH} levels deep")
        _check(tree)
        if program_size(tree.body)[1] > MAX_DEPTH:
            raise ExpressionError(f"expression is nested more than {MAX_DEPTH} levels deep")
        self.text = text
        self._body = tree.body

    def __call__(self, t):
        """Evaluate at t (scalar or array); float64 result of t's shape."""
        t_arr = np.asarray(t, dtype=float)
        with np.errstate(all="ignore"):
            value = _interpret(self._body, t_arr, {})
        return np.broadcast_to(np.asarray(value, dtype=float), t_arr.shape).copy()

    def derivative(self) -> "Expression":
        """d/dt of the expression, as an expression (functions that jump, sign and heaviside, count as flat);
        ExpressionError when its program would exceed MAX_PROGRAM operations."""
        derived = Expression.__new__(Expression)
        derived._body = _derive(self._body)
        size, depth = program_size(derived._body)
        if size > MAX_PROGRAM:
            raise ExpressionError(f"its derivative takes {size} operations to evaluate (limit {MAX_PROGRAM}); "
                                  "simplify the expression, or give the derivative itself")
        derived.text = f"d/dt ({self.text})"
        return derived

    def edges(self, t0: float, t1: float, limit: int | None = None) -> np.ndarray:
        """Sorted times in (t0, t1) where the expression may jump or kink: where an argument of sign, heaviside or
        abs changes sign. Found on a sampling that doubles until the count settles, then bisected to adjacent
        floats; each time is the first float on the far side, so the value just before it is the left limit.
        TooManyEdges as soon as a sampling sees more than `limit`, before any is located."""
        key = (float(t0), float(t1))
        cache = self.__dict__.setdefault("_edges", {})
        if key not in cache:
            cache[key] = _edges(self._body, *key, limit=limit)
        if limit is not None and len(cache[key]) > limit:
            raise TooManyEdges(len(cache[key]))
        return cache[key]

    def program(self) -> tuple[list[int], list[float], int]:
        """The checked tree as a postfix program: opcodes, the constants OP_CONST pushes in order, stack depth."""
        codes: list[int] = []
        constants: list[float] = []
        depth = _postfix(self._body, codes, constants)
        return codes, constants, depth


# ----------------------------------------------------------- edges

EDGE_FUNCTIONS = ("sign", "heaviside", "abs")  # a jump, a jump, a kink where the argument crosses zero
EDGE_SAMPLES = (2**12, 2**22)  # the first sampling of (t0, t1) and the finest
EDGE_WORK = 2**27  # node evaluations of one sampling (about 0.5 s): a large expression is sampled less finely


class TooManyEdges(ExpressionError):
    """More edges than a run may restart at; `count` is how many were seen (a lower bound)."""

    def __init__(self, count: int):
        self.count = count
        super().__init__(f"at least {count} edges")


def _edges(body: ast.AST, t0: float, t1: float, limit: int | None = None) -> np.ndarray:
    arguments = [node.args[0] for node in _unique_nodes(body)
                 if isinstance(node, ast.Call) and node.func.id in EDGE_FUNCTIONS and _has_t(node.args[0])]
    if not arguments or not t1 > t0:
        return np.empty(0)
    cost = sum(1 for n in _unique_nodes(ast.Tuple(arguments)))  # each shared node is evaluated once a sampling
    finest = max(EDGE_SAMPLES[0], min(EDGE_SAMPLES[1], EDGE_WORK // max(cost, 1)))
    samples, counted = EDGE_SAMPLES[0], -1
    with np.errstate(all="ignore"):
        while True:
            t = np.linspace(t0, t1, samples + 1)
            memo: dict = {}
            brackets = []
            for argument in arguments:
                side = np.asarray(_interpret(argument, t, memo) >= 0)
                change = np.flatnonzero(side[1:] != side[:-1])
                brackets.append((argument, t[change], t[change + 1], side[change]))
            count = sum(len(lo) for _, lo, _, _ in brackets)
            if limit is not None and count > limit:
                raise TooManyEdges(count)
            # settled, and fine enough that edges are far apart in samples (a coarse sampling aliases)
            if (count == counted and samples >= 32 * count) or samples >= finest:
                break
            samples, counted = 2 * samples, count
        found = [_bisect(argument, lo, hi, before) for argument, lo, hi, before in brackets]
    times = np.unique(np.concatenate(found))
    times = times[(times > t0) & (times < t1)]
    if len(times) > 1:  # edges of several arguments at one instant (a float apart) are one edge: the last
        times = times[np.concatenate([np.diff(times) > 1e-12 * max(1.0, abs(t1)), [True]])]
    return times


def _unique_nodes(tree: ast.AST):
    """Every node of a tree whose subtrees may be shared, once each."""
    seen, stack = set(), [tree]
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        yield node
        stack.extend(ast.iter_child_nodes(node))


def _bisect(argument: ast.AST, lo: np.ndarray, hi: np.ndarray, before: np.ndarray) -> np.ndarray:
    """Narrow each bracket of a sign change of argument to adjacent floats; the floats on the far side."""
    while True:
        mid = lo + 0.5 * (hi - lo)
        open_ = (mid > lo) & (mid < hi)
        if not open_.any():
            return hi
        near = np.asarray(_interpret(argument, mid, {}) >= 0) == before
        lo = np.where(open_ & near, mid, lo)
        hi = np.where(open_ & ~near, mid, hi)


# ----------------------------------------------------------- differentiation


def _number(node: ast.AST) -> float | None:
    return float(node.value) if isinstance(node, ast.Constant) else None


def _const(value: float) -> ast.AST:
    return ast.Constant(value) if value >= 0 else ast.UnaryOp(ast.USub(), ast.Constant(-value))


def _add(a: ast.AST, b: ast.AST, op=ast.Add) -> ast.AST:
    if _number(b) == 0.0:
        return a
    if _number(a) == 0.0:
        return b if op is ast.Add else ast.UnaryOp(ast.USub(), b)
    return ast.BinOp(a, op(), b)


def _mul(a: ast.AST, b: ast.AST) -> ast.AST:
    if _number(a) == 0.0 or _number(b) == 0.0:
        return ast.Constant(0.0)
    if _number(a) == 1.0:
        return b
    if _number(b) == 1.0:
        return a
    return ast.BinOp(a, ast.Mult(), b)


def _call(name: str, arg: ast.AST) -> ast.AST:
    return ast.Call(ast.Name(name, ast.Load()), [arg], [])


def _has_t(node: ast.AST) -> bool:
    return any(isinstance(n, ast.Name) and n.id == "t" for n in _unique_nodes(node))


def _derive(node: ast.AST) -> ast.AST:
    """The derivative in t of a checked tree, by the chain rule; each shared subtree is differentiated once."""
    derived: dict[int, tuple[ast.AST, ast.AST]] = {}
    timed: dict[int, tuple[ast.AST, bool]] = {}

    def has_t(n: ast.AST) -> bool:
        if id(n) not in timed:
            timed[id(n)] = (n, (isinstance(n, ast.Name) and n.id == "t") or any(map(has_t, _operands(n))))
        return timed[id(n)][1]

    def d(n: ast.AST) -> ast.AST:
        if id(n) not in derived:
            derived[id(n)] = (n, _derive_one(n, d, has_t))
        return derived[id(n)][1]

    return d(node)


def _derive_one(node: ast.AST, d, has_t) -> ast.AST:
    """One node's derivative; d differentiates its operands, has_t tells whether a subtree depends on t."""
    if not has_t(node):
        return ast.Constant(0.0)
    if isinstance(node, ast.Name):
        return ast.Constant(1.0)
    if isinstance(node, ast.UnaryOp):
        inner = d(node.operand)
        return ast.UnaryOp(ast.USub(), inner) if isinstance(node.op, ast.USub) and _number(inner) != 0.0 else inner
    if isinstance(node, ast.BinOp):
        u, v = node.left, node.right
        du, dv = d(u), d(v)
        if isinstance(node.op, (ast.Add, ast.Sub)):
            return _add(du, dv, type(node.op))
        if isinstance(node.op, ast.Mult):
            return _add(_mul(du, v), _mul(u, dv))
        if isinstance(node.op, ast.Div):  # (du v - u dv) / v^2
            top = _add(_mul(du, v), _mul(u, dv), ast.Sub)
            return ast.BinOp(top, ast.Div(), ast.BinOp(v, ast.Pow(), ast.Constant(2.0)))
        if not has_t(v):  # u^c: c u^(c-1) du
            return _mul(_mul(v, ast.BinOp(u, ast.Pow(), ast.BinOp(v, ast.Sub(), ast.Constant(1.0)))), du)
        # u^v = exp(v log u): u^v (dv log u + v du / u)
        inner = _add(_mul(dv, _call("log", u)), ast.BinOp(_mul(v, du), ast.Div(), u))
        return _mul(node, inner)
    if isinstance(node, ast.Call):
        name, u = node.func.id, node.args[0]
        du = d(u)
        outer = {
            "sin": lambda: _call("cos", u),
            "cos": lambda: ast.UnaryOp(ast.USub(), _call("sin", u)),
            "tan": lambda: ast.BinOp(ast.Constant(1.0), ast.Div(), ast.BinOp(_call("cos", u), ast.Pow(), ast.Constant(2.0))),
            "exp": lambda: node,
            "log": lambda: ast.BinOp(ast.Constant(1.0), ast.Div(), u),
            "sqrt": lambda: ast.BinOp(ast.Constant(0.5), ast.Div(), node),
            "abs": lambda: _call("sign", u),
            "sign": lambda: ast.Constant(0.0),
            "heaviside": lambda: ast.Constant(0.0),
            "tanh": lambda: ast.BinOp(ast.Constant(1.0), ast.Sub(), ast.BinOp(node, ast.Pow(), ast.Constant(2.0))),
        }[name]()
        return _mul(outer, du)
    raise AssertionError("unchecked node")
