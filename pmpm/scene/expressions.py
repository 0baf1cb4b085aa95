"""Arithmetic expressions of a scene, parsed and never run as code.

A scene may give an initial velocity component as a string such as ``"0.1 * sin(pi * x / 50)"``.
The string is parsed with :mod:`ast` and only this small language is accepted:

- numbers (finite, magnitude at most :data:`MAX_CONSTANT`), the coordinates ``x`` and ``y``
  and the constants ``pi`` and ``e``;
- ``+ - * /``, ``**`` with a number (or a negated number) of magnitude at most
  :data:`MAX_EXPONENT` as exponent, unary ``-`` and ``+``, parentheses;
- calls of the functions in :data:`FUNCTIONS` with positional arguments.

Anything else (attribute access, subscripts, names other than the above, keywords, comparisons,
lambdas, comprehensions, strings, ...) is refused with the reason. The text is at most
:data:`MAX_LENGTH` characters and :data:`MAX_NODES` syntax nodes, so evaluation is a bounded
number of vectorised numpy operations over the particle coordinates: no expression can loop,
allocate without bound or reach Python objects. Evaluation happens in float64 with numpy's
warnings silenced; the caller refuses non-finite results (:func:`evaluate` can do it).
"""
import ast
import math

import numpy as np

from pmpm.errors import ConfigError

__all__ = ["Expression", "parse_expression", "FUNCTIONS", "MAX_LENGTH", "MAX_NODES",
           "MAX_EXPONENT", "MAX_CONSTANT"]

#: longest accepted expression text (characters)
MAX_LENGTH = 500
#: most syntax nodes in one expression (bounds the work of an evaluation)
MAX_NODES = 200
#: largest magnitude of a ``**`` exponent
MAX_EXPONENT = 16.0
#: largest magnitude of a number literal
MAX_CONSTANT = 1e15

#: name -> (numpy function, number of arguments)
FUNCTIONS = {
    "sin": (np.sin, 1), "cos": (np.cos, 1), "tan": (np.tan, 1),
    "asin": (np.arcsin, 1), "acos": (np.arccos, 1), "atan": (np.arctan, 1), "atan2": (np.arctan2, 2),
    "sinh": (np.sinh, 1), "cosh": (np.cosh, 1), "tanh": (np.tanh, 1),
    "exp": (np.exp, 1), "log": (np.log, 1), "log10": (np.log10, 1), "sqrt": (np.sqrt, 1),
    "abs": (np.abs, 1), "sign": (np.sign, 1), "floor": (np.floor, 1), "ceil": (np.ceil, 1),
    "min": (np.minimum, 2), "max": (np.maximum, 2),
}
CONSTANTS = {"pi": math.pi, "e": math.e}
VARIABLES = ("x", "y")

_BINARY = {ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide,
           ast.Pow: np.power}
_UNARY = {ast.USub: np.negative, ast.UAdd: np.positive}


def _number(node):
    """The value of a literal number node (``3``, ``-2.5``), else None."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _number(node.operand)
        return None if inner is None else (-inner if isinstance(node.op, ast.USub) else inner)
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return float(node.value)
    return None


class _Refused(Exception):
    pass


def _check(node):
    """Raise _Refused with the reason if ``node`` is outside the language."""
    if isinstance(node, ast.Expression):
        return _check(node.body)
    if isinstance(node, ast.Constant):
        # bool is an int subclass; str, bytes, complex, None, Ellipsis are not numbers
        if type(node.value) not in (int, float):
            raise _Refused(f"{type(node.value).__name__} literal not allowed (only numbers)")
        if isinstance(node.value, int) and abs(node.value) > MAX_CONSTANT:
            raise _Refused(f"number too large (at most {MAX_CONSTANT:g} in magnitude)")
        value = float(node.value)
        if not math.isfinite(value) or abs(value) > MAX_CONSTANT:
            raise _Refused(f"number too large or not finite (at most {MAX_CONSTANT:g} in magnitude)")
        return
    if isinstance(node, ast.Name):
        if node.id not in VARIABLES and node.id not in CONSTANTS:
            raise _Refused(f"unknown name {node.id!r} (allowed: x, y, pi, e and the functions "
                           f"{', '.join(FUNCTIONS)})")
        return
    if isinstance(node, ast.BinOp):
        if type(node.op) not in _BINARY:
            raise _Refused(f"operator {type(node.op).__name__} not allowed (only + - * / **)")
        if isinstance(node.op, ast.Pow):
            p = _number(node.right)
            if p is None:
                raise _Refused("the exponent of ** must be a number")
            if abs(p) > MAX_EXPONENT:
                raise _Refused(f"exponent {p:g} too large (at most {MAX_EXPONENT:g} in magnitude)")
        _check(node.left)
        _check(node.right)
        return
    if isinstance(node, ast.UnaryOp):
        if type(node.op) not in _UNARY:
            raise _Refused(f"operator {type(node.op).__name__} not allowed")
        return _check(node.operand)
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            what = repr(node.func.id) if isinstance(node.func, ast.Name) else "anything but a named function"
            raise _Refused(f"cannot call {what} (allowed: {', '.join(FUNCTIONS)})")
        if node.keywords:
            raise _Refused(f"{node.func.id}() takes no keyword arguments")
        arity = FUNCTIONS[node.func.id][1]
        if len(node.args) != arity or any(isinstance(a, ast.Starred) for a in node.args):
            raise _Refused(f"{node.func.id}() takes {arity} argument(s)")
        for a in node.args:
            _check(a)
        return
    raise _Refused(f"{type(node).__name__} not allowed (only numbers, x, y, + - * / **, "
                   f"parentheses and functions)")


class Expression:
    """A parsed expression in ``x`` and ``y``.

    Parameters
    ----------
    text : str
        The source, already checked by :func:`parse_expression`.
    tree : ast.Expression
    """

    def __init__(self, text, tree):
        self.text = text
        self._tree = tree

    def __repr__(self):
        return f"Expression({self.text!r})"

    def __call__(self, x, y):
        """Evaluate vectorised over coordinate arrays ``x`` and ``y`` (same shape).

        Returns
        -------
        numpy.ndarray
            float64 values, the shape of ``x`` (a constant expression is broadcast).
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        with np.errstate(all="ignore"):
            out = self._eval(self._tree.body, x, y)
        return np.broadcast_to(np.asarray(out, dtype=np.float64), x.shape).copy()

    def _eval(self, node, x, y):
        if isinstance(node, ast.Constant):
            return np.float64(node.value)
        if isinstance(node, ast.Name):
            return x if node.id == "x" else y if node.id == "y" else np.float64(CONSTANTS[node.id])
        if isinstance(node, ast.BinOp):
            return _BINARY[type(node.op)](self._eval(node.left, x, y), self._eval(node.right, x, y))
        if isinstance(node, ast.UnaryOp):
            return _UNARY[type(node.op)](self._eval(node.operand, x, y))
        fn = FUNCTIONS[node.func.id][0]
        return fn(*(self._eval(a, x, y) for a in node.args))

    def evaluate(self, x, y, key):
        """Evaluate and refuse a non-finite value with a ConfigError naming ``key``."""
        out = self(x, y)
        bad = ~np.isfinite(out)
        if bad.any():
            k = int(np.argmax(bad.reshape(-1)))
            px, py = np.broadcast_to(x, out.shape).reshape(-1)[k], np.broadcast_to(y, out.shape).reshape(-1)[k]
            raise ConfigError(key, f"expression {self.text!r} is not finite at "
                                   f"(x, y) = ({px:g}, {py:g})")
        return out


def parse_expression(text, key):
    """Parse ``text`` into an :class:`Expression`; a ConfigError naming ``key`` if refused.

    The refusal reason never repeats more than the (length-bounded) expression itself.
    """
    if not isinstance(text, str):
        raise ConfigError(key, "must be a number or an expression string")
    if len(text) > MAX_LENGTH:
        raise ConfigError(key, f"expression longer than {MAX_LENGTH} characters")
    if not text.strip():
        raise ConfigError(key, "empty expression")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, MemoryError, RecursionError):
        raise ConfigError(key, "expression is not valid arithmetic syntax") from None
    count = sum(1 for _ in ast.walk(tree))
    if count > MAX_NODES:
        raise ConfigError(key, f"expression too long ({count} syntax nodes, at most {MAX_NODES})")
    try:
        _check(tree)
    except _Refused as exc:
        raise ConfigError(key, f"expression refused: {exc}") from None
    except RecursionError:
        raise ConfigError(key, "expression nested too deeply") from None
    return Expression(text, tree)
