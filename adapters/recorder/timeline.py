"""``Timeline``: when each recorded message is due in a replay — its publish time
from the window's start — with no wait longer than ``max_gap_s``: a longer gap
(a quiet hour, a frame stamped an hour ahead) is shortened to ``max_gap_s``,
and time that jumps back further than that goes on from where it was.

>>> line = Timeline(max_gap_s=5.0)
>>> [tuple(round(x, 2) for x in line.place(s)) for s in (0.0, 0.02, 3600.04, 0.06, 0.08)]
[(0.0, 0.0), (0.02, 0.0), (5.02, 3600.02), (5.02, -3599.98), (5.04, 0.0)]
>>> round(line.shift_s, 2)  # the replay runs 4.96 s longer than the recording's 0.08 s
-4.96
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Timeline:
    """The replay's timeline: ``place`` each message's publish time, in the order they are replayed."""

    max_gap_s: float
    front_s: float = 0.0   # the latest time placed so far
    shift_s: float = 0.0   # all that was cut out so far (negative: time that went back)

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
