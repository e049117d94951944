"""Reassembling frames: the joint samples one robot took at one instant share
``t`` and ``seq``; a frame is complete when every key seen in earlier frames
has arrived, when a newer frame starts, or after ``max_wait_s``.

>>> frames = FrameAssembler()
>>> frames.add("pepper", "pepper/joints/HeadYaw", 7, 1.0, 0.1)    # keys of a frame: not known yet
[]
>>> [f.seq for f in frames.add("pepper", "pepper/joints/HeadYaw", 8, 1.01, 0.2)]
[7, 8]

Frame 8 closed 7 and, now that a frame is known to hold just HeadYaw, itself.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Frame:
    """One robot's samples of one instant: key → item (whatever the caller stores)."""

    robot: str
    seq: int
    t: float
    values: dict[str, Any] = field(default_factory=dict)
    opened: float = field(default_factory=time.monotonic)


class FrameAssembler:
    """Groups samples into frames per robot; counts samples that come too late."""

    def __init__(self, max_wait_s: float = 0.05) -> None:
        self.max_wait_s = max_wait_s
        self.late = 0
        self.open: dict[str, Frame] = {}  # robot → its frame still open (read it, never change it)
        self._expected: dict[str, frozenset[str]] = {}
        self._closed: dict[str, tuple[int, float]] = {}  # robot → (seq, t) of the frame closed last

    def add(self, robot: str, key: str, seq: int, t: float, item: Any) -> list[Frame]:
        """Add a sample; returns the frames it completed (zero, one or two)."""
        return self.extend(robot, seq, t, {key: item})

    def extend(self, robot: str, seq: int, t: float, items: dict[str, Any]) -> list[Frame]:
        """Add several samples of one frame at once (a frame that came whole, to be
        joined by the derived values of its ``seq``); returns the frames completed."""
        done: list[Frame] = []
        frame = self.open.get(robot)
        if frame is not None and seq != frame.seq:
            if seq < frame.seq and t < frame.t:  # a straggler from an earlier frame
                self.late += 1
                return done
            done.append(self._close(robot))  # a newer frame (or a restarted stream)
            frame = None
        if frame is None and self._closed.get(robot) == (seq, t):  # its frame closed without it
            self.late += 1
            return done
        if frame is None:
            frame = self.open[robot] = Frame(robot, seq, t)
        frame.values.update(items)
        expected = self._expected.get(robot)
        if expected and expected <= frame.values.keys():
            done.append(self._close(robot))
        return done

    def whole(self, robot: str, seq: int, t: float, keys: frozenset[str]) -> bool:
        """Whether a frame that came whole, with ``keys``, is complete by itself: none of
        ``robot``'s is open and its frames hold just these keys (no derived values join
        them). It is then taken as closed without being built (a sample of its ``seq``
        that comes later is late), and the caller sends it as it is."""
        expected = self._expected.get(robot)
        if robot in self.open or (expected is not keys and expected != keys):
            return False
        if expected is not keys:  # (equal: kept as the caller's, whose next frame's are the same object)
            self._expected[robot] = keys
        self._closed[robot] = (seq, t)
        return True

    def expire(self, now: float | None = None) -> list[Frame]:
        """Frames open for longer than ``max_wait_s`` (their stream paused or lost keys)."""
        now = time.monotonic() if now is None else now
        stale = [r for r, f in self.open.items() if now - f.opened >= self.max_wait_s]
        return [self._close(r) for r in stale]

    def next_expiry(self) -> float | None:
        return min((f.opened + self.max_wait_s for f in self.open.values()), default=None)

    def _close(self, robot: str) -> Frame:
        """Close a frame; the keys a frame holds only grow, so one lost sample
        does not make the next frame close early."""
        frame = self.open.pop(robot)
        self._expected[robot] = self._expected.get(robot, frozenset()) | frame.values.keys()
        self._closed[robot] = (frame.seq, frame.t)
        return frame
