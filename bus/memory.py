"""Giving back what glibc's malloc keeps after a burst.

    trimmer = Trimmer()        # None-safe: does nothing where there is no glibc or /proc
    while running:
        trimmer.check()        # at most once a second; trims when RSS grew by GROWN since

A burst of messages on Zenoh's threads and the nodes' workers (a flood, a stall's
backlog) allocates on up to 8 malloc arenas per core, one per thread that allocates
at the time. When the burst is over, what it freed stays mapped in those arenas, and
the next burst allocates on other threads' arenas: the process's resident size keeps
the high-water mark of every arena, though Python and Zenoh hold none of it. The bus
fuzz campaign measured it (``sonibus run`` with every node, glibc's ``mallinfo2``):
80 MB free in the arenas for 40 MB in use after the campaign; ``malloc_trim(0)``
gave back 45 MB of it in one call. So the runner calls ``malloc_trim`` every second
for ``AFTER_S`` once the resident size grew by ``GROWN``: a burst frees most of what it
took only as it ends, often after the trim its growth set off (which then finds little
free). A steady show does not grow: one small read of /proc a second, no call.
"""

from __future__ import annotations

import ctypes
import logging
import os
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

CHECK_EVERY_S = 1.0  # how often the resident size is read (one small read of /proc)
GROWN = 8 << 20      # bytes of growth (since the last trim) that make trims worth their few ms
AFTER_S = 10.0       # trims go on this long after the last such growth (what the burst frees as it ends)
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
_STATM = Path("/proc/self/statm")


def resident() -> int | None:
    """This process's resident set size in bytes (None: no /proc)."""
    try:
        return int(_STATM.read_text().split()[1]) * _PAGE
    except (OSError, IndexError, ValueError):
        return None


def _malloc_trim() -> Any:
    try:
        trim = ctypes.CDLL(None).malloc_trim  # glibc only (not musl, not macOS)
    except (AttributeError, OSError):
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


class Trimmer:
    """Calls glibc's ``malloc_trim(0)`` every ``every_s`` for ``after_s`` once the resident
    size grew by ``grown`` bytes over what the last call left; does nothing without glibc
    or /proc. ``check`` is cheap when nothing grew: one read of /proc/self/statm."""

    def __init__(self, every_s: float = CHECK_EVERY_S, grown: int = GROWN, after_s: float = AFTER_S) -> None:
        self.every_s, self.grown, self.after_s = every_s, grown, after_s
        self._until = -1.0
        self._trim = _malloc_trim()
        self._floor = resident() if self._trim is not None else None
        self._next = 0.0
        self.trims = 0          # calls made
        self.released = 0       # bytes the resident size fell by in them

    @property
    def active(self) -> bool:
        return self._floor is not None

    def check(self, now: float | None = None) -> int | None:
        """Trim if due; the bytes it gave back (None: not due, or nothing grew)."""
        now = time.monotonic() if now is None else now
        if self._floor is None or now < self._next:
            return None
        self._next = now + self.every_s
        size = resident()
        if size is None:
            return None
        if size >= self._floor + self.grown:
            self._until = now + self.after_s
        elif now >= self._until:
            self._floor = min(self._floor, size)  # (it shrank: growth counts from there)
            return None
        started = time.perf_counter()
        self._trim(0)  # (ctypes lets go of the GIL: Python threads run meanwhile)
        after = resident() or size
        self._floor = after
        self.trims += 1
        self.released += max(0, size - after)
        log.debug("malloc_trim: resident %.1f → %.1f MB in %.1f ms", size / 1e6, after / 1e6,
                  (time.perf_counter() - started) * 1000)
        return size - after

    def __repr__(self) -> str:
        return (f"<Trimmer {'on' if self.active else 'off (no glibc or /proc)'}, {self.trims} trims, "
                f"{self.released / 1e6:.0f} MB given back>")
