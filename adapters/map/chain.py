"""One map at run time: its sources' latest values in, one output (and maybe a
trigger) out, through the steps of its ``MapSpec``:

    source → fraction of its range (``from``, else calibrated, else its info's) → clip 0..1
    → expression (several sources) → clip 0..1 → invert → curve → destination range
    → smoothing (one-pole or one-euro) → rate limit → clip window → clamp to the range
    → deadband → threshold

Nothing not finite passes (a source's NaN or infinity, an expression's overflow:
counted ``not_finite`` and dropped), and the output is clamped to its declared
range whatever happens before.

>>> from .config import parse_map
>>> cutoff = Chain(parse_map("cutoff", {"source": "pepper/derived/hand/R.z", "to": [200, 2000], "curve": "exp"}))
>>> cutoff.feed("x", 0.5, (0.0, 1.0), 0.0) and round(cutoff.compute(0.0).value, 3)
632.456
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from .config import MapSpec
from .expr import ERRORS
from .steps import Calibration, Deadband, OneEuro, OnePole, RateLimit, Threshold


class Output(NamedTuple):
    """What one computation gives: the value to publish (None: within the deadband) and
    the threshold's change (``"on"``, ``"off"`` or None)."""

    value: float | None
    trigger: str | None
    fraction: float   # the curve's input, 0..1 (for views)


def _nothing(kind: str, n: int = 1) -> None:
    """A ``count`` that counts nothing (a chain used on its own)."""


class Chain:
    """The running state of one map (``feed`` each source value, then ``compute``)."""

    def __init__(self, spec: MapSpec, count: Callable[[str, int], None] = _nothing) -> None:
        self.spec = spec
        self.count = count
        self.values: dict[str, float] = {}   # source name → its latest value as a fraction 0..1
        self.calibrations = {s.name: Calibration(spec.calibrate_s) for s in spec.sources} if spec.calibrate_s else {}
        self.smoother: OnePole | OneEuro | None = None
        if spec.smooth_ms:
            self.smoother = OnePole(spec.smooth_ms / 1000.0)
        elif spec.one_euro:
            self.smoother = OneEuro(*spec.one_euro)
        self.limiter = RateLimit(spec.rate_limit) if spec.rate_limit else None
        self.deadband = Deadband(spec.deadband) if spec.deadband else None
        self.threshold = Threshold(*spec.threshold) if spec.threshold else None
        self.value: float | None = None      # the last output
        # (what compute reads each time, read once: a node runs 50 maps at 100 Hz)
        self._single = spec.sources[0].name if spec.expr is None else ""
        self._count = len(spec.sources)
        self._to = spec.to
        self._window = spec.clip or (spec.low, spec.high)
        self._tolerance = 1e-9 * (spec.high - spec.low)
        self.frozen: list[tuple[str, tuple[float, float]]] = []  # calibrations frozen since last asked

    def span(self, name: str, info: tuple[float, float] | None) -> tuple[float, float] | None:
        """The range a source's values are taken in: ``from``, else calibrated, else its info's."""
        given = self.spec.ranges.get(name)
        if given is not None:
            return given
        calibration = self.calibrations.get(name)
        return calibration.range if calibration is not None else info

    def feed(self, name: str, raw: float, info: tuple[float, float] | None, t: float) -> bool:
        """Take source ``name``'s value ``raw`` (at ``t``; its info's range ``info``); False if it
        cannot be used: not finite (counted), or no range known yet."""
        if not math.isfinite(raw):
            self.count("not_finite", 1)
            return False
        calibration = self.calibrations.get(name)
        if calibration is not None and calibration(t, raw):
            self.frozen.append((name, calibration.range))  # type: ignore[arg-type]
        span = self.span(name, info)
        if span is None:
            return False
        low, high = span
        x = (raw - low) / (high - low)
        if x != x:  # NaN: both overflowed (a calibrated span of ±1e308); in halves they do not
            x = (0.5 * raw - 0.5 * low) / (0.5 * high - 0.5 * low)
        self.values[name] = 0.0 if x <= 0.0 else 1.0 if x >= 1.0 else x  # (x may be ±inf: a tiny calibrated span)
        return True

    def compute(self, t: float) -> Output | None:
        """The output at ``t`` from the sources' latest values; None while a source has
        none yet, or when the expression fails or gives something not finite (counted)."""
        spec = self.spec
        if len(self.values) < self._count:
            return None
        if self._single:
            x = self.values[self._single]
        else:
            try:
                x = spec.expr(self.values)
            except ERRORS:
                self.count("expr_errors", 1)
                return None
            if not math.isfinite(x):
                self.count("not_finite", 1)
                return None
            x = 0.0 if x <= 0.0 else 1.0 if x >= 1.0 else x
        if spec.invert:
            x = 1.0 - x
        lo, hi = self._to
        y = lo + (hi - lo) * spec.curve(x)
        if not math.isfinite(y):  # (never into a filter: a NaN in its state would stop the map for good)
            self.count("not_finite", 1)
            return None
        if self.smoother is not None:
            y = self.smoother(t, y)
        if self.limiter is not None:
            y = self.limiter(t, y)
        low, high = self._window
        if not math.isfinite(y):  # (cannot happen with finite steps; if it did, it does not leave)
            self.count("not_finite", 1)
            return None
        clamped = low if y < low else high if y > high else y
        if clamped != y and abs(clamped - y) > self._tolerance:  # (not a rounding's last bit)
            self.count("clamped", 1)
        y = clamped
        trigger = self.threshold(y) if self.threshold is not None else None
        value = self.deadband(y) if self.deadband is not None else y
        if value is not None:
            self.value = value
        return Output(value, trigger, x)
