"""A node's counters and figures, and the stats message built from them each second.

``Counters`` are added to from any thread and read like a dict; a counter can
also follow a number kept elsewhere (a queue's drops), read when it is read.
``Latencies`` keeps a bounded sample of one interval's latencies (a reservoir,
not every sample). ``Report`` turns both into the message a node publishes on
``sonibus/stats/<host>/<node>`` (schema ``node_stats``).

>>> counters = Counters(("received", "bad"))
>>> counters.add("received", 3)
>>> counters["received"], counters.get("written", 0), dict(counters)
(3, 0, {'received': 3, 'bad': 0})
>>> counters == {"received": 3}  # a counter at zero equals one not kept (as collections.Counter)
True
"""

from __future__ import annotations

import math
import os
import random
import resource
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

BASE = ("received", "sent", "dropped", "stale", "bad", "errors")  # every node has these
RESERVOIR = 256  # latencies kept per interval
PAGE = os.sysconf("SC_PAGE_SIZE")


class Counters(Mapping[str, int]):
    """Named counters, thread-safe: ``add`` from any thread, read like a dict."""

    def __init__(self, names: Iterable[str] = ()) -> None:
        self._lock = threading.Lock()
        self._counts: dict[str, int] = dict.fromkeys(names, 0)
        self._sources: dict[str, list[Callable[[], int]]] = {}

    def declare(self, names: Iterable[str]) -> None:
        """Keep ``names`` from now on, at zero until counted (so zeros show)."""
        with self._lock:
            for name in names:
                self._counts.setdefault(name, 0)

    def add(self, name: str, n: int = 1) -> None:
        with self._lock:
            self._counts[name] = self._counts.get(name, 0) + n

    def tally(self, names: Iterable[str]) -> dict[str, int]:
        """Counters ``names`` kept in a plain dict that its owner adds to (``tally[name] += n``)
        under a lock of its own, one thread at a time (a sink's state lock): no lock taken per
        count, a few per frame fewer on a sink's path. They are read with the rest.

        >>> counters = Counters(("sent",))
        >>> tally = counters.tally(("sent",))
        >>> tally["sent"] += 17
        >>> counters["sent"]
        17
        """
        kept = dict.fromkeys(names, 0)
        for name in kept:
            self.follow(name, lambda name=name: kept[name])
        return kept

    def counting(self, tally: dict[str, int]) -> Callable[[str, int], None]:
        """A ``count(name, n)`` that adds to ``tally`` (``tally``'s) the names it keeps, under
        its owner's lock, and to these counters the others: what a sink gives ``Streams.take``
        on its frames' path, where ``received`` is counted every frame.

        >>> counters = Counters(("bad",))
        >>> count = counters.counting(counters.tally(("received",)))
        >>> count("received", 17); count("bad", 1)
        >>> counters["received"], counters["bad"]
        (17, 1)
        """
        def count(name: str, n: int = 1) -> None:
            if name in tally:
                tally[name] += n
            else:
                self.add(name, n)
        return count

    def follow(self, name: str, source: Callable[[], int]) -> None:
        """Add ``source()`` (a count kept elsewhere, e.g. a queue's drops) to ``name`` when read."""
        with self._lock:
            self._counts.setdefault(name, 0)
            self._sources.setdefault(name, []).append(source)

    def __getitem__(self, name: str) -> int:
        with self._lock:
            count = self._counts[name]
            sources = self._sources.get(name, ())
        return count + sum(source() for source in sources)

    def __iter__(self) -> Iterator[str]:
        with self._lock:
            return iter(list(self._counts))

    def __len__(self) -> int:
        return len(self._counts)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Mapping):
            return NotImplemented
        return {k: v for k, v in self.items() if v} == {k: v for k, v in other.items() if v}

    __hash__ = None  # type: ignore[assignment]  # mutable

    def __repr__(self) -> str:
        return f"Counters({dict(self)})"


class Latencies:
    """A uniform sample (at most ``size``) of the latencies seen since the last ``take``.

    Reservoir sampling by Li's algorithm L: once the sample is full, how many latencies
    to pass over before the next one kept is drawn at once, so most latencies draw no
    random number (a sink adds one a frame).

    ``add`` takes no lock: it appends to a deque (atomic under the GIL, from any thread)
    and every ``FOLD`` latencies they are folded into the sample under the lock, popped
    one by one (each popped by one folder only, as many as were there when it began);
    ``take`` folds what is left first. Every latency is counted once, in the interval of
    the ``take`` that folds it: exactly as if each ``add`` took the lock.

    >>> latencies = Latencies(size=4)
    >>> for ms in range(1000):
    ...     latencies.add(ms / 1000)
    >>> taken = latencies.take()
    >>> taken["samples"], len(latencies._kept)
    (1000, 0)
    """

    FOLD = 64  # latencies added between two folds (at most this many wait, besides what threads add meanwhile)

    def __init__(self, size: int = RESERVOIR) -> None:
        self._size = size
        self._lock = threading.Lock()
        self._fresh: deque[float] = deque()  # added, not yet folded into the sample
        self._kept: list[float] = []
        self._seen = 0
        self._next = 0      # the count at which the next latency is kept (once the sample is full)
        self._weight = 1.0  # algorithm L's W

    def add(self, seconds: float) -> None:
        fresh = self._fresh
        fresh.append(seconds)
        if len(fresh) >= self.FOLD:
            self._fold()

    def _fold(self) -> None:
        with self._lock:
            self._fold_locked()

    def _fold_locked(self) -> None:
        """The latencies added so far, into the sample (each seen latency kept with the same chance)."""
        popleft, kept, size = self._fresh.popleft, self._kept, self._size
        for _ in range(len(self._fresh)):  # (only folders pop, under the lock: these many are there)
            seconds = popleft()
            self._seen += 1
            if len(kept) < size:
                kept.append(seconds)
                if len(kept) == size:
                    self._skip()
            elif self._seen == self._next:
                kept[random.randrange(size)] = seconds
                self._skip()

    def _skip(self) -> None:
        """Draw the next latency to keep (algorithm L)."""
        self._weight *= math.exp(math.log(_uniform()) / self._size)
        self._next = self._seen + 1 + int(math.log(_uniform()) / math.log1p(-self._weight))

    def take(self) -> dict[str, float] | None:
        """p50 and p99 in ms of the sample, and how many were seen; None if none; starts over."""
        with self._lock:
            self._fold_locked()
            kept, seen = sorted(self._kept), self._seen
            self._kept, self._seen, self._next, self._weight = [], 0, 0, 1.0
        if not kept:
            return None
        return {"p50": round(_quantile(kept, 0.50) * 1000.0, 3), "p99": round(_quantile(kept, 0.99) * 1000.0, 3),
                "samples": seen}


def _uniform() -> float:
    """A random number in (0, 1)."""
    return random.random() or 0.5


def _quantile(ordered: list[float], q: float) -> float:
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def rss_bytes() -> int:
    """The process's resident memory (``/proc/self/statm``; peak RSS where there is no /proc)."""
    try:
        with open("/proc/self/statm", encoding="ascii") as statm:
            return int(statm.read().split()[1]) * PAGE
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


@dataclass
class Report:
    """Builds a node's stats messages: counters, their rates and the process's CPU
    over the interval since the previous message, latencies, memory."""

    counters: Counters
    latencies: Latencies = field(default_factory=Latencies)
    _wall: float = field(default_factory=time.monotonic, init=False)
    _cpu: float = field(default_factory=time.process_time, init=False)
    _last: dict[str, int] = field(default_factory=dict, init=False)

    def next(self, node: dict[str, Any], metrics: dict[str, Any], advance: bool = True) -> dict[str, Any]:
        """The message for the interval that ends now (with ``advance=False``: so far, and the
        interval goes on); ``node`` gives host, node, adapter, state, since and restarts; ``metrics`` the
        adapter's own figures."""
        now, cpu, counts = time.monotonic(), time.process_time(), dict(self.counters)
        interval = max(now - self._wall, 1e-9)
        message: dict[str, Any] = {
            "t": time.time(), "host": node["host"], "node": node["node"], "adapter": node["adapter"],
            "state": node["state"], "uptime_s": round(max(0.0, time.time() - node["since"]), 3),
            "interval_s": round(interval, 3), "counters": counts,
            "rates": {k: round((v - self._last.get(k, 0)) / interval, 2) for k, v in counts.items()},
            "process": {"pid": os.getpid(), "cpu_percent": round(100.0 * (cpu - self._cpu) / interval, 1),
                        "rss_bytes": rss_bytes(), "restarts": node.get("restarts", 0)},
        }
        latency = self.latencies.take() if advance else None
        if latency is not None:
            message["latency_ms"] = latency
        if metrics:
            message["metrics"] = metrics
        if advance:
            self._wall, self._cpu, self._last = now, cpu, counts
        return message
