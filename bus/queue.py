"""A bounded sample queue fed by a Zenoh callback: newest kept, oldest dropped.

Bounded in items and in bytes: a payload may be up to the gate's 64 KiB, so 8,192
waiting items could hold 512 MiB; past ``max_bytes`` of payloads the oldest go too.

Zenoh runs every callback of a session on shared threads, so a callback must
only enqueue; the consumer works on its own thread and can be woken to stop.
An item can also be held until a time (``hold``): a sink's frame that came too
soon after the one before waits for its turn there (``bus/pacing.py``), and the
consumer's ``get``/``drain`` hand it out when it is due, waking for it.

>>> queue = SampleQueue()
>>> queue.hold("pepper/frame", ("pepper/frame", b"older"), due=0.0)
False
>>> queue.hold("pepper/frame", ("pepper/frame", b"newer"), due=0.0)  # replaces the one held
True
>>> queue.put(("pepper/events/x", b"event"))
>>> queue.drain()  # what was held and is due comes first
[('pepper/frame', b'newer'), ('pepper/events/x', b'event')]
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

MAX_BYTES = 32 << 20  # of payloads waiting in one queue (a flood of 64 KiB frames at a stalled sink)
ITEM_BYTES = 64       # what an item is counted beside its payload's bytes (or alone, with no bytes payload)


def item_size(item: Any) -> int:
    """Bytes ``item`` is counted as: its payload's (a ``(key, bytes, ...)`` tuple, as a
    subscription queues), and ``ITEM_BYTES``."""
    if item.__class__ is tuple and len(item) > 1 and item[1].__class__ is bytes:
        return len(item[1]) + ITEM_BYTES
    return ITEM_BYTES


class SampleQueue:
    """``put`` never blocks: when full (``maxlen`` items, or ``max_bytes`` of payloads),
    the oldest items are dropped and counted."""

    def __init__(self, maxlen: int = 1024, max_bytes: int = MAX_BYTES) -> None:
        if maxlen < 1:
            raise ValueError(f"queue length must be at least 1, got {maxlen}")
        self._items: deque[Any] = deque(maxlen=maxlen)
        self.max_bytes = max_bytes
        self.bytes = 0  # of the items waiting (not the held ones: at most one per slot, each replaced)
        self._held: dict[str, tuple[float, Any]] = {}  # slot → (due, item), at most maxlen
        self._ready = threading.Condition()
        self._closed = False
        self._woken = False  # ``wake`` called: the waiting consumer (or the next one) returns at once
        self.dropped = 0
        self._filled = self._taken = time.monotonic()  # when it last went from empty to not; last get/drain

    @property
    def maxlen(self) -> int:
        """The most items it keeps waiting (and, apart, the most it holds: ``hold``)."""
        return self._items.maxlen or 0

    def put(self, item: Any) -> None:
        size = item_size(item)
        with self._ready:
            if not self._items:
                self._filled = time.monotonic()
            while self._items and (len(self._items) == self._items.maxlen or self.bytes + size > self.max_bytes):
                self.bytes -= item_size(self._items.popleft())
                self.dropped += 1
            self._items.append(item)
            self.bytes += size
            if len(self._items) == 1:  # only an empty queue has someone to wake
                self._ready.notify()

    def hold(self, slot: str, item: Any, due: float) -> bool:
        """Give ``item`` out once ``time.monotonic()`` reaches ``due``; an item held
        for ``slot`` already is replaced (True is returned then). Never blocks; past
        ``maxlen`` slots the one held longest is dropped and counted."""
        with self._ready:
            replaced = self._held.pop(slot, None) is not None
            if not replaced and len(self._held) >= self._items.maxlen:
                del self._held[next(iter(self._held))]
                self.dropped += 1
            self._held[slot] = (due, item)
            self._ready.notify()  # a consumer waiting recomputes when to wake
            return replaced

    def get(self, timeout: float | None = None) -> Any | None:
        """The oldest item (one held and due first), or None when closed, after
        ``timeout`` seconds, or when woken to look at a newly held item (or by ``wake``)."""
        with self._ready:
            if not self._items and not self._closed and not self._woken:
                self._ready.wait(self._until(timeout))
            self._woken = False
            self._taken = time.monotonic()
            if self._held:
                due = self._due(1)
                if due:
                    return due[0]
            if not self._items:
                return None
            item = self._items.popleft()
            self.bytes -= item_size(item)
            return item

    def drain(self, timeout: float | None = None) -> list[Any]:
        """Every item waiting (held and due ones first, then oldest first), waiting up to
        ``timeout`` for one: a consumer that takes a frame's samples in one go wakes once,
        not per sample."""
        with self._ready:
            if not self._items and not self._closed and not self._woken:
                self._ready.wait(self._until(timeout))
            self._woken = False
            self._taken = time.monotonic()
            items = self._due() if self._held else []
            items += self._items
            self._items.clear()
            self.bytes = 0
            return items

    def _until(self, timeout: float | None) -> float | None:
        """How long to wait: ``timeout``, or less if a held item falls due sooner."""
        if not self._held:
            return timeout
        soonest = max(0.0, min(due for due, _ in self._held.values()) - time.monotonic())
        return soonest if timeout is None else min(timeout, soonest)

    def _due(self, most: int | None = None) -> list[Any]:
        """Held items that are due (at most ``most``), taken out, soonest first."""
        now = time.monotonic()
        due = sorted((d, slot) for slot, (d, _) in self._held.items() if d <= now)[:most]
        return [self._held.pop(slot)[1] for _, slot in due]

    def wake(self) -> None:
        """Make the consumer waiting in ``get`` or ``drain`` (or the next one to wait) return now
        with what there is, maybe nothing: something it looks at beside the items changed (a
        token came, a held frame fell due sooner). No item is put: a flood of wake-ups (a
        stranger's tokens) pushes no message out of a full queue."""
        with self._ready:
            self._woken = True
            self._ready.notify_all()

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
        return len(self._items) + len(self._held)
