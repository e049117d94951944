"""What the robot plays when nobody asks, and when its motors let it: pure logic
on the show's clock (seconds), with no bus and no robot.

Motors need rest: the sim's old ``autoplay_s = 20`` was about 4,300 gestures a
day. ``Budget`` holds the next gesture back until ``rest_s`` after the end of the
previous one, and until fewer than ``per_hour`` gestures started in the hour
before it (scenarios' behaviors count too: after a busy hour at the kiosk, the
robot plays less on its own).

>>> budget = Budget(rest_s=120, per_hour=2)
>>> budget.next_at(0.0)
0.0
>>> budget.started(0.0); budget.ended(5.0); budget.next_at(6.0)      # resting
125.0
>>> budget.started(125.0); budget.ended(130.0); budget.next_at(250.0)  # two in the hour: the cap
3600.0
>>> order = Order(["a", "b", "c"], "in order", seed="2025-06-03")
>>> [order.next() for _ in range(4)]
['a', 'b', 'c', 'a']
"""

from __future__ import annotations

import random
from collections import deque
from collections.abc import Sequence

HOUR_S = 3600.0


class Budget:
    """When the next gesture may start: ``rest_s`` after the previous one ended, and
    at most ``per_hour`` starts in any hour (a sliding hour, not the clock's)."""

    def __init__(self, rest_s: float, per_hour: int) -> None:
        if rest_s < 0 or per_hour < 1:
            raise ValueError(f"rest_s {rest_s:g} must be ≥ 0 and per_hour {per_hour} ≥ 1")
        self.rest_s, self.per_hour = rest_s, per_hour
        self._starts: deque[float] = deque()
        self._last_end: float | None = None

    def started(self, at: float) -> None:
        """A gesture started at ``at`` (an idle one, or a scenario's behavior)."""
        self._starts.append(at)
        while len(self._starts) > self.per_hour:  # (only the last per_hour can hold the next one back)
            self._starts.popleft()

    def ended(self, at: float) -> None:
        """The gesture under way ended at ``at`` (done, failed, or cut short: the motors worked)."""
        self._last_end = at

    def next_at(self, now: float) -> float:
        """The earliest time, ``now`` or later, at which the next gesture may start."""
        earliest = now
        if self._last_end is not None:
            earliest = max(earliest, self._last_end + self.rest_s)
        if len(self._starts) >= self.per_hour:
            earliest = max(earliest, self._starts[-self.per_hour] + HOUR_S)
        return earliest

    def in_last_hour(self, now: float) -> int:
        """Gestures started in the hour before ``now``."""
        return sum(1 for start in self._starts if start > now - HOUR_S)


class Order:
    """The idle behaviors one after the other: ``in order``, or ``random`` — each round
    of the list shuffled, never the same behavior twice in a row. The shuffle is drawn
    from ``seed`` (the show's date), so a rehearsal of a day plays what that day will."""

    def __init__(self, behaviors: Sequence[str], order: str, seed: str) -> None:
        if not behaviors:
            raise ValueError("no idle behaviors")
        self.behaviors, self.order = list(behaviors), order
        self._random = random.Random(seed)
        self._round: list[str] = []
        self._last = ""

    def next(self) -> str:
        if not self._round:
            self._round = list(self.behaviors)
            if self.order == "random":
                self._random.shuffle(self._round)
                if len(self._round) > 1 and self._round[0] == self._last:
                    self._round.append(self._round.pop(0))
        self._last = self._round.pop(0)
        return self._last
