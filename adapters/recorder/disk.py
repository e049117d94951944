"""The disk guard: the free space where a recorder writes, against two thresholds.

Below ``warn_free_mb`` the disk is ``low`` (the recorder warns once); below
``min_free_mb`` it is ``full`` (the recorder finishes its file and pauses, the
rest of the show goes on). A full disk is ``full`` until twice ``min_free_mb``
is free again (at least 1 MB more than ``min_free_mb``), so a recorder that
pauses does not start a file, fill it and pause again every second.

>>> free = {"now": 5_000_000}
>>> guard = DiskGuard(warn_free_mb=4, min_free_mb=2, free_bytes=lambda folder: free["now"])
>>> guard.check("."), guard.level
(None, 'ok')
>>> free["now"] = 3_000_000; guard.check(".")
'low'
>>> free["now"] = 1_000_000; guard.check(".")
'full'
>>> free["now"] = 3_500_000; guard.check("."), guard.level  # not yet twice min_free_mb
(None, 'full')
>>> free["now"] = 4_200_000; guard.check(".")
'ok'
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable

MB = 1_000_000


class DiskGuard:
    """``check(folder)`` says when the level changes: ``ok``, ``low`` or ``full``."""

    def __init__(self, warn_free_mb: float, min_free_mb: float,
                 free_bytes: Callable[[str], int | None] = lambda folder: _free(folder)) -> None:
        self.warn = int(warn_free_mb * MB)
        self.min = int(min_free_mb * MB)
        self.resume = self.min + max(self.min, MB)
        self.level = "ok"
        self.free: int | None = None  # bytes, at the last check (None: not known)
        self._free_bytes = free_bytes

    def check(self, folder: str) -> str | None:
        """Measure the free space of the file system holding ``folder`` (or the nearest
        folder above it that is there); the new level if it changed, else None."""
        try:
            self.free = self._free_bytes(_existing(folder))
        except OSError:  # (a disk gone: the writer's error says it)
            self.free = None
        if self.free is None:
            return None
        if self.free < self.min or (self.level == "full" and self.free < self.resume):
            level = "full"
        else:
            level = "low" if self.free < self.warn else "ok"
        changed, self.level = level != self.level, level
        return level if changed else None

    def left(self, rate: float) -> str:
        """How long until ``full`` at ``rate`` bytes/s: ``about 4 min at 26 kB/s``; "" unknown.

        >>> DiskGuard(4, 2, free_bytes=lambda folder: 2_500_000).left(1000.0)
        ''
        >>> guard = DiskGuard(4, 2, free_bytes=lambda folder: 2_500_000); guard.check("."); guard.left(1000.0)
        'low'
        'about 8 min at 1 kB/s'
        """
        if self.free is None or rate <= 0:
            return ""
        seconds = max(0.0, (self.free - self.min) / rate)
        took = f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min" if seconds < 7200 \
            else f"{seconds / 3600:.1f} h"
        return f"about {took} at {rate / 1e3:.0f} kB/s"

    def describe(self, folder: str) -> str:
        """``1.2 MB free on /srv/recordings``."""
        if self.free is None:
            return f"free space not known on {_existing(folder)}"
        return f"{self.free / MB:.1f} MB free on {_existing(folder)}"


def _free(folder: str) -> int | None:
    """Bytes free for files in ``folder``; None on a file system that does not count
    them (``/proc``: its size is 0)."""
    usage = shutil.disk_usage(folder)
    return usage.free if usage.total else None


def _existing(folder: str) -> str:
    folder = os.path.abspath(folder)
    while not os.path.isdir(folder) and os.path.dirname(folder) != folder:
        folder = os.path.dirname(folder)
    return folder
