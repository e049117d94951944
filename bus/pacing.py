"""Drift-free pacing: a loop on absolute deadlines that skips, never bursts.

>>> import threading
>>> stop, seen = threading.Event(), []
>>> def tick(frame: int) -> None:
...     seen.append(frame)
...     if len(seen) == 3:
...         stop.set()
>>> Pacer(200.0).run(tick, stop)
0
>>> seen
[0, 1, 2]
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class Pacer:
    """Calls ``tick(frame)`` at ``rate_hz`` against deadlines fixed at the start.

    A tick that comes back late by more than a period (a slow robot, a VM
    stall) makes the loop skip the frames it missed: ``frame`` jumps, so the
    gap shows in ``seq``, and no frame is ever sent twice as fast to catch up."""

    def __init__(self, rate_hz: float) -> None:
        if not rate_hz > 0:
            raise ValueError(f"rate {rate_hz} Hz must be more than 0")
        self.period = 1.0 / rate_hz
        self.skipped = 0

    def run(self, tick: Callable[[int], None], stop: threading.Event) -> int:
        """Loop until ``stop`` is set; returns the number of frames skipped."""
        start = time.monotonic()
        frame = 0
        while not stop.is_set():
            tick(frame)
            frame += 1
            late = time.monotonic() - (start + frame * self.period)
            if late > self.period:
                missed = int(late / self.period)
                frame += missed
                self.skipped += missed
            stop.wait(max(0.0, start + frame * self.period - time.monotonic()))
        return self.skipped
