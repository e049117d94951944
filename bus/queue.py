"""A bounded sample queue fed by a Zenoh callback: newest kept, oldest dropped.

Zenoh runs every callback of a session on shared threads, so a callback must
only enqueue; the consumer works on its own thread and can be woken to stop.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any


class SampleQueue:
    """``put`` never blocks: when full, the oldest item is dropped and counted."""

    def __init__(self, maxlen: int = 1024) -> None:
        if maxlen < 1:
            raise ValueError(f"queue length must be at least 1, got {maxlen}")
        self._items: deque[Any] = deque(maxlen=maxlen)
        self._ready = threading.Condition()
        self._closed = False
        self.dropped = 0
        self._filled = self._taken = time.monotonic()  # when it last went from empty to not; last get/drain

    def put(self, item: Any) -> None:
        with self._ready:
            if len(self._items) == self._items.maxlen:
                self.dropped += 1
            elif not self._items:
                self._filled = time.monotonic()
            self._items.append(item)
            if len(self._items) == 1:  # only an empty queue has someone to wake
                self._ready.notify()

    def get(self, timeout: float | None = None) -> Any | None:
        """The oldest item, or None when closed or after ``timeout`` seconds."""
        with self._ready:
            if not self._items and not self._closed:
                self._ready.wait(timeout)
            self._taken = time.monotonic()
            return self._items.popleft() if self._items else None

    def drain(self, timeout: float | None = None) -> list[Any]:
        """Every item waiting (oldest first), waiting up to ``timeout`` for one: a
        consumer that takes a frame's samples in one go wakes once, not per sample."""
        with self._ready:
            if not self._items and not self._closed:
                self._ready.wait(timeout)
            self._taken = time.monotonic()
            items = list(self._items)
            self._items.clear()
            return items

    def close(self) -> None:
        with self._ready:
            self._closed = True
            self._ready.notify_all()

    def stalled_s(self) -> float:
        """How long items have waited with nobody taking any (0 when none waits, or closed):
        a consumer that is busy with one item, or hung, lets this grow."""
        with self._ready:
            if not self._items or self._closed:
                return 0.0
            return time.monotonic() - max(self._filled, self._taken)

    @property
    def closed(self) -> bool:
        return self._closed

    def __len__(self) -> int:
        return len(self._items)
