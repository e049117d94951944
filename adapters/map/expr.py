"""How a map combines several sources: a small expression such as ``max(a, b)``,
``a * b`` or ``hypot(a, b)``, evaluated by ``simpleeval`` (a maintained safe
evaluator of Python expressions: no attribute access, no imports, no ``eval``),
parsed once when the map is made, its names checked against the map's sources.

>>> combine = Expression("hypot(a, b) / sqrt(2)", ("a", "b"))
>>> round(combine({"a": 1.0, "b": 1.0}), 6)
1.0
>>> Expression("a + c", ("a", "b"))
Traceback (most recent call last):
...
ValueError: 'a + c' names 'c', which is no source of this map — sources: a, b
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping

import simpleeval

MAX_LENGTH = 500  # characters of an expression (one line of a file)


def _clip(x: float, lo: float, hi: float) -> float:
    return min(hi, max(lo, x))


FUNCTIONS = {  # what an expression may call, documented in docs/mapping.md
    "min": min, "max": max, "abs": abs, "hypot": math.hypot, "sqrt": math.sqrt,
    "exp": math.exp, "log": math.log, "sin": math.sin, "cos": math.cos, "clip": _clip,
    "mean": lambda *xs: sum(xs) / len(xs),
}
ERRORS = (ArithmeticError, ValueError, TypeError, simpleeval.InvalidExpression)  # what an evaluation may raise


class Expression:
    """A checked expression over the names ``names``; call it with their values."""

    def __init__(self, text: str, names: tuple[str, ...]) -> None:
        if len(text) > MAX_LENGTH:
            raise ValueError(f"is {len(text)} characters long, at most {MAX_LENGTH}")
        self.text = text
        self._eval = simpleeval.SimpleEval(functions=FUNCTIONS, names={})
        try:
            self._parsed = self._eval.parse(text)
        except SyntaxError as exc:
            raise ValueError(f"'{text}' is not an expression: {exc.msg}") from None
        for node in ast.walk(self._parsed):
            if isinstance(node, ast.Name) and node.id not in names and node.id not in FUNCTIONS:
                raise ValueError(f"'{text}' names '{node.id}', which is no source of this map — "
                                 f"sources: {', '.join(names)}")
            if isinstance(node, ast.Call) and not (isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS):
                raise ValueError(f"'{text}' calls something that is not one of {', '.join(FUNCTIONS)}")
            if isinstance(node, ast.Attribute | ast.Subscript | ast.Lambda | ast.comprehension):
                raise ValueError(f"'{text}' uses {type(node).__name__.lower()}s: only numbers, names, operators "
                                 f"and {', '.join(FUNCTIONS)}")
        self.names = names
        try:  # (the types of what it does: a number comes out of numbers)
            self({n: 0.5 for n in names})
        except ERRORS as exc:
            raise ValueError(f"'{text}' fails on sample values 0.5: {type(exc).__name__}: {exc}") from None

    def __call__(self, values: Mapping[str, float]) -> float:
        """The expression's value; raises one of ``ERRORS`` (a division by 0...)."""
        self._eval.names = values
        out = self._eval.eval(self.text, previously_parsed=self._parsed)
        if isinstance(out, bool) or not isinstance(out, int | float):
            raise TypeError(f"gave {out!r}, not a number")
        return float(out)

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"
