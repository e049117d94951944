"""``Timeline``: when each recorded message is due in a replay — its publish time
from the window's start — with no wait longer than ``max_gap_s``: a longer gap
(a quiet hour, a frame stamped an hour ahead) is shortened to ``max_gap_s``,
and time that jumps back further than that goes on from where it was.

A publish time is taken as it is only while it agrees, within
``STRAY_S``, with when the message was recorded (plus the publisher's usual
clock offset); one that strays is replaced by the latter: several publishers whose ``t`` disagree, or one stamping at
random, would otherwise make the replay wait back and forth
(``when``).

>>> line = Timeline(max_gap_s=5.0)
>>> [tuple(round(x, 2) for x in line.place(s)) for s in (0.0, 0.02, 3600.04, 0.06, 0.08)]
[(0.0, 0.0), (0.02, 0.0), (5.02, 3600.02), (5.02, -3599.98), (5.04, 0.0)]
>>> round(line.shift_s, 2)  # the replay runs 4.96 s longer than the recording's 0.08 s
-4.96
"""

from __future__ import annotations

import statistics
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

STRAY_S = 0.5   # how far a publish time may stray from its log time (plus the usual offset)
OFFSETS = 64    # publish − log offsets the usual one is the median of


@dataclass
class Timeline:
    """The replay's timeline: ``place`` each message's publish time (or ``when`` it
    agrees with its log time), in the order they are replayed."""

    max_gap_s: float
    front_s: float = 0.0   # the latest time placed so far
    shift_s: float = 0.0   # all that was cut out so far (negative: time that went back)
    _offsets: deque[float] = field(default_factory=lambda: deque(maxlen=OFFSETS))
    _offset_s: float = 0.0
    _seen: int = 0

    def prime(self, offsets: Iterable[float]) -> None:
        """Start from the publish − log offsets of the first messages to come, so one
        that strays at the very start is not taken for the usual one."""
        self._offsets.extend(offsets)
        if self._offsets:
            self._offset_s = statistics.median(self._offsets)
            self._seen = OFFSETS

    def when(self, publish_s: float, log_s: float) -> float:
        """The time to place a message at: its publish time if that is within ``STRAY_S``
        of its log time plus the usual publish − log offset (the median of the last
        ones), else that log time plus the usual offset.

        >>> line = Timeline(5.0)
        >>> [line.when(p, log) for p, log in ((10.0, 10.0), (10.1, 10.1), (70.0, 10.2), (10.3, 10.3))]
        [10.0, 10.1, 10.2, 10.3]
        """
        self._offsets.append(publish_s - log_s)
        self._seen += 1
        if self._seen <= 16 or self._seen % 16 == 0:  # (unprimed: the first ones; then every 16th)
            self._offset_s = statistics.median(self._offsets)
        expected = log_s + self._offset_s
        return publish_s if abs(publish_s - expected) <= STRAY_S else expected

    def place(self, at_s: float) -> tuple[float, float]:
        """``at_s`` (seconds from the window's start on the recording's clock) on the
        replay's timeline, and the gap that was cut before it (0.0: none)."""
        offset = at_s - self.shift_s
        gap = offset - self.front_s
        if gap > self.max_gap_s:
            cut = gap - self.max_gap_s
        elif gap < -self.max_gap_s:
            cut = gap
        else:
            cut = 0.0
        self.shift_s += cut
        offset -= cut
        self.front_s = max(self.front_s, offset)
        return offset, gap if cut else 0.0
