"""What each robot's info says of its values' ranges, for the OSC sink's targets of
normalized values (``values = "normalized"``): a value goes out as a fraction of its
range once its robot's info came, and a derived value its info does not describe yet is
held back a while (a receiver of 0..1 cannot tell metres from fractions).

>>> from sonibus.adapters.osc import scale
>>> ranges = RobotRanges()
>>> info = {"joints": [{"name": "HeadYaw", "min": -2.0, "max": 2.0}], "derived": []}
>>> ranges.keep("pepper", info, scale.ranges(info))
True
>>> from sonibus.bus.keys import Key
>>> ranges.scaled(Key.parse("pepper/joints/HeadYaw"), (1.0,)), ranges.scaled(Key.parse("nao/joints/HeadYaw"), (1.0,))
((0.75,), None)
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from sonibus.bus.keys import Key

from . import scale

MAX_ROBOTS = 1024  # robots whose info (ranges) is kept: names made up on the bus must not grow it
UNDESCRIBED_WAIT_S = 3.0  # a derived value no info describes is held back this long at most, then sent raw
MAX_FIRST_SEEN = 4096  # undescribed derived values remembered (names made up on the fly must not grow it)


class RobotRanges:
    """Each robot's ranges (``scale.ranges`` of its info), by name, and the derived values
    its info describes (ranged or not), for at most ``MAX_ROBOTS`` robots."""

    def __init__(self) -> None:
        self.spans: dict[str, dict[str, tuple[float, float]]] = {}  # robot → name → (min, max)
        self._described: dict[str, set[str]] = {}  # robot → derived values its info describes
        self._first_seen: dict[tuple[str, str], float] = {}  # (robot, derived value) → when it first came

    def keep(self, robot: str, info: dict[str, Any], spans: dict[str, tuple[float, float]]) -> bool:
        """``robot``'s ranges, ``spans`` (``scale.ranges`` of its ``info``); False when they are
        not kept: ``MAX_ROBOTS`` robots' are already."""
        if robot not in self.spans and len(self.spans) >= MAX_ROBOTS:
            return False
        self.spans[robot] = spans
        self._described[robot] = {str(d.get("name")) for d in info.get("derived", []) if isinstance(d, dict)}
        return True

    def describes(self, robot: str, name: str) -> bool:
        """Whether ``robot``'s info describes derived value ``name`` (``feature/name``)."""
        return name in self._described.get(robot, ())

    def scaled(self, source: Key, values: Sequence[float]) -> Sequence[float] | None:
        """``values`` of ``source`` as fractions of its range (as they are: a value without
        one); None while its robot's info has not come, or a derived value it does not
        describe yet (``UNDESCRIBED_WAIT_S`` after it first came, still undescribed, a
        script's own derived key, it goes as it is)."""
        spans = self.spans.get(source.robot)
        if spans is None:
            return None
        name = source.name if source.section == "joints" else f"{source.feature}/{source.name}"
        span = spans.get(name)
        if span is None and source.section == "derived" and self._undescribed(source.robot, name):
            return None
        return values if span is None else scale.normalized(values, span)

    def _undescribed(self, robot: str, name: str) -> bool:
        if self.describes(robot, name):
            return False
        if len(self._first_seen) > MAX_FIRST_SEEN:
            self._first_seen.clear()
        first = self._first_seen.setdefault((robot, name), time.monotonic())
        return time.monotonic() - first < UNDESCRIBED_WAIT_S
