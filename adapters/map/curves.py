"""Curves: a fraction 0..1 in, a fraction 0..1 out (the map then scales it to its
destination range). Each is a closed form, so a test and the docs can state it.

>>> round(Exp(10.0)(0.5), 6), round(Log(10.0)(0.5), 6), S()(0.25), Points(((0, 0), (0.5, 1), (1, 1)))(0.25)
(0.240253, 0.740363, 0.15625, 0.5)
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

CURVES = ("linear", "exp", "log", "s", "points")
MAX_POINTS = 1_000  # a breakpoint curve's points (a curve drawn by hand has tens; 10,000 is a mistake or a flood)


@dataclass(frozen=True)
class Linear:
    """``f(x) = x``."""

    def __call__(self, x: float) -> float:
        return x


@dataclass(frozen=True)
class Exp:
    """``f(x) = (r^x − 1) / (r − 1)``: equal steps of ``x`` multiply the output by equal
    ratios. With ``r`` the ratio of the destination's ends (200..2000 Hz: 10) the map's
    output is ``lo · r^x`` exactly: 200, 632, 2000 for 0, ½, 1 — a filter sweep by ear."""

    base: float

    def __call__(self, x: float) -> float:
        r = self.base
        return (r ** x - 1.0) / (r - 1.0)


@dataclass(frozen=True)
class Log:
    """``f(x) = log(1 + (r − 1)·x) / log(r)``: the inverse of ``Exp`` with the same ``r``
    (fast first, then slower)."""

    base: float

    def __call__(self, x: float) -> float:
        r = self.base
        return math.log1p((r - 1.0) * x) / math.log(r)


@dataclass(frozen=True)
class S:
    """``f(x) = 3x² − 2x³`` (smoothstep): slow at both ends, fastest in the middle."""

    def __call__(self, x: float) -> float:
        return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class Points:
    """Breakpoints ``(x, y)``, ``x`` increasing: straight lines between them, the first
    and last ``y`` outside them."""

    points: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "_xs", [p[0] for p in self.points])

    def __call__(self, x: float) -> float:
        xs: list[float] = self._xs  # type: ignore[attr-defined]
        i = bisect.bisect_right(xs, x)
        if i == 0:
            return self.points[0][1]
        if i == len(xs):
            return self.points[-1][1]
        (x0, y0), (x1, y1) = self.points[i - 1], self.points[i]
        return y0 + (y1 - y0) * (x - x0) / (x1 - x0)


Curve = Linear | Exp | Log | S | Points


def default_base(to: tuple[float, float]) -> float:
    """The ``r`` of ``exp`` and ``log`` when none is given: the ratio of the destination's
    ends when both have one sign (200..2000 → 10), else 10."""
    lo, hi = to
    if lo * hi > 0 and lo != hi:
        return hi / lo
    return 10.0
