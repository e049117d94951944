"""The stateful steps of a map's chain, each on one stream of numbers with times
(seconds, the samples' own ``t``): smoothing (one-pole, one-euro), rate limit,
deadband, threshold with hysteresis, calibration. Pure: no bus, no clock.

>>> pole = OnePole(0.080)
>>> pole(0.0, 0.0), round(pole(0.010, 1.0), 6)       # 1 − e^(−10/80)
(0.0, 0.117503)
>>> trigger = Threshold(on=0.8, off=0.6)
>>> [trigger(v) for v in (0.7, 0.85, 0.7, 0.9, 0.5)]
[None, 'on', None, None, 'off']
"""

from __future__ import annotations

import math

MIN_DT = 1e-4  # a sample at the same time as the last (or before it): taken as 0.1 ms later


def _dt(last: float | None, t: float) -> float:
    return MIN_DT if last is None or not t - last > MIN_DT else t - last


class _Timed:
    """A step on values with times: the first value passes, each next one is ``_next(y, x, dt)``
    of the last output ``y``."""

    def __init__(self) -> None:
        self.y: float | None = None
        self.t: float | None = None

    def __call__(self, t: float, x: float) -> float:
        self.y = x if self.y is None else self._next(self.y, x, _dt(self.t, t))
        self.t = t
        return self.y

    def _next(self, y: float, x: float, dt: float) -> float:
        raise NotImplementedError


class OnePole(_Timed):
    """One-pole low-pass with time constant ``tau`` s: ``y += (1 − e^(−dt/τ))·(x − y)``,
    so a step reaches 63 % in ``tau`` whatever the sample rate; the first sample passes."""

    def __init__(self, tau: float) -> None:
        super().__init__()
        self.tau = tau

    def _next(self, y: float, x: float, dt: float) -> float:
        return y - math.expm1(-dt / self.tau) * (x - y)


def smoothing_factor(cutoff_hz: float, dt: float) -> float:
    """The one-euro filter's ``α = 1 / (1 + τ/T_e)`` with ``τ = 1 / (2π·f_c)`` (Casiez et al. 2012, eq. 1-2)."""
    tau = 1.0 / (2.0 * math.pi * cutoff_hz)
    return 1.0 / (1.0 + tau / dt)


class OneEuro:
    """The 1€ filter (Casiez, Roussel, Vogel: "1€ Filter: A Simple Speed-based Low-pass
    Filter for Noisy Input in Interactive Systems", CHI 2012): an exponential smoother
    whose cut-off rises with the signal's speed, ``f_c = min_cutoff + beta·|dx̂|``, the
    speed itself smoothed at ``d_cutoff``. Slow movements: little jitter; fast ones:
    little lag. The first sample passes; its speed is 0."""

    def __init__(self, min_cutoff: float = 1.0, beta: float = 0.0, d_cutoff: float = 1.0) -> None:
        self.min_cutoff, self.beta, self.d_cutoff = min_cutoff, beta, d_cutoff
        self.x: float | None = None
        self.dx = 0.0
        self.t: float | None = None

    def __call__(self, t: float, x: float) -> float:
        if self.x is None:
            self.x, self.t = x, t
            return x
        dt = _dt(self.t, t)
        a_d = smoothing_factor(self.d_cutoff, dt)
        self.dx = a_d * (x - self.x) / dt + (1.0 - a_d) * self.dx
        a = smoothing_factor(self.min_cutoff + self.beta * abs(self.dx), dt)
        self.x = a * x + (1.0 - a) * self.x
        self.t = t
        return self.x


class RateLimit(_Timed):
    """At most ``per_s`` of change per second: ``y = y₀ + clamp(x − y₀, ±per_s·dt)``."""

    def __init__(self, per_s: float) -> None:
        super().__init__()
        self.per_s = per_s

    def _next(self, y: float, x: float, dt: float) -> float:
        step = self.per_s * dt
        return y + min(step, max(-step, x - y))


class Deadband:
    """A change smaller than ``width`` from the last value let through is no change (None)."""

    def __init__(self, width: float) -> None:
        self.width = width
        self.last: float | None = None

    def __call__(self, x: float) -> float | None:
        if self.last is not None and abs(x - self.last) < self.width:
            return None
        self.last = x
        return x


class Threshold:
    """A Schmitt trigger: ``'on'`` when the value reaches ``on``, ``'off'`` when it falls
    back to ``off`` (below ``on``), None otherwise: a value hovering at the threshold
    triggers once."""

    def __init__(self, on: float, off: float) -> None:
        self.on, self.off = on, off
        self.state = False

    def __call__(self, x: float) -> str | None:
        if not self.state and x >= self.on:
            self.state = True
            return "on"
        if self.state and x <= self.off:
            self.state = False
            return "off"
        return None


class Calibration:
    """Learn a source's real range: the lowest and highest values of its first
    ``seconds`` (from its first sample's ``t``), then frozen. ``range`` is None until
    two different values came."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.start: float | None = None
        self.low = math.inf
        self.high = -math.inf
        self.frozen = False

    def __call__(self, t: float, x: float) -> bool:
        """Take one value; True when this one froze the range."""
        if self.frozen:
            return False
        if self.start is None:
            self.start = t
        if t - self.start >= self.seconds and self.range is not None:
            self.frozen = True
            return True
        self.low, self.high = min(self.low, x), max(self.high, x)
        return False

    @property
    def range(self) -> tuple[float, float] | None:
        return (self.low, self.high) if self.high > self.low else None
