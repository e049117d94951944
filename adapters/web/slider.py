"""Slider moves coalesced: at most one per key each ``period``, the latest wins.

A slider dragged in a browser sends a joint command per pixel; a robot needs the
latest position, a few tens of times a second. ``offer`` sends at once when the key
(robot, joints) has been quiet for a period, else holds the item and sends it when
the period is over; an item still held when a newer one comes is handed back
(superseded), and ``cancel`` hands back every held item (a stop: nothing may move
a robot after it).

Runs on one asyncio loop (its ``call_later`` and ``time``), as the web server's
handlers do.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

MAX_KEYS = 4096  # keys remembered; past this the quiet ones are forgotten


@dataclass
class _Lane:
    last: float = -1e18                       # when its latest item was sent (the loop's clock)
    held: Any = None
    timer: asyncio.TimerHandle | None = None


class Coalescer:
    """``send(item)`` at most once per ``period`` per key; the latest item wins."""

    def __init__(self, loop: asyncio.AbstractEventLoop, period: float, send: Callable[[Any], None]) -> None:
        self.loop, self.period, self.send = loop, period, send
        self._lanes: dict[Hashable, _Lane] = {}

    def offer(self, key: Hashable, item: Any) -> Any:
        """Send ``item`` now or when the period of ``key`` is over; the item it supersedes
        (held, never sent), or None."""
        lane = self._lanes.get(key)
        if lane is None:
            if len(self._lanes) >= MAX_KEYS:
                self._forget_quiet()
            lane = self._lanes[key] = _Lane()
        superseded, lane.held = lane.held, item
        if lane.timer is None:
            wait = lane.last + self.period - self.loop.time()
            if wait <= 0:
                self._flush(key)
            else:
                lane.timer = self.loop.call_later(wait, self._flush, key)
        return superseded

    def cancel(self) -> list[Any]:
        """Forget every held item; they are returned (never sent)."""
        held = []
        for lane in self._lanes.values():
            if lane.timer is not None:
                lane.timer.cancel()
                lane.timer = None
            if lane.held is not None:
                held.append(lane.held)
                lane.held = None
        return held

    def _flush(self, key: Hashable) -> None:
        lane = self._lanes[key]
        item, lane.held, lane.timer = lane.held, None, None
        if item is not None:
            lane.last = self.loop.time()
            self.send(item)

    def _forget_quiet(self) -> None:
        now = self.loop.time()
        self._lanes = {k: lane for k, lane in self._lanes.items()
                       if lane.timer is not None or now - lane.last < self.period}
