"""Recordings for days: the files of one recording, when a recorder moves on to
the next, and what each is called.

A file is named by ``path`` with ``{time}`` replaced by when the file starts
(local time, ``20261122-140501``), so ``ls`` lists a show's files in order. A
new file starts every ``rotate_s`` seconds from the start of the current one
and/or once the current one holds ``rotate_mb`` (its size on disk: chunks
reach it every ``flush_s``); never twice in one second (the names would be the
same: a file that reaches its size early grows until the next second). A
name that is taken all the same (the clock set back, the hour that repeats
when daylight saving time ends, a recorder restarted within its second) gets
``-2``, ``-3``... before its extension: a recorder never writes over a file it
did not start with (a fixed ``path`` without ``{time}`` with ``overwrite``: its
first file only).

>>> Names("recordings/show-{time}.mcap").at(time.mktime((2026, 11, 22, 14, 5, 1, 0, 0, -1)))
'recordings/show-20261122-140501.mcap'
>>> Names("show.mcap").at(0.0, taken=lambda p: p in ("show.mcap", "show-2.mcap"))
'show-3.mcap'
>>> policy = Rotation(rotate_s=3600, rotate_mb=0)
>>> policy.due(age_s=3599.0, size=10**9), policy.due(age_s=3600.0, size=0)
('', 'after 3600 s')
>>> Rotation(rotate_s=0, rotate_mb=100).due(age_s=1.0, size=100_000_000)
'at 100 MB'
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .writer import BadRecord, RecordingWriter

TIME = "{time}"
TIME_FORMAT = "%Y%m%d-%H%M%S"


@dataclass(frozen=True)
class Names:
    """The files ``pattern`` names (``{time}``: when each starts)."""

    pattern: str

    def at(self, now: float, taken: Callable[[str], bool] = lambda path: False) -> str:
        """The name of a file that starts at ``now`` (epoch s); the first of ``-2``, ``-3``...
        that is not ``taken`` if the plain name is."""
        path = self.pattern.replace(TIME, time.strftime(TIME_FORMAT, time.localtime(now)))
        stem, extension = os.path.splitext(path)
        n = 1
        while taken(path):
            n += 1
            path = f"{stem}-{n}{extension}"
        return path


@dataclass(frozen=True)
class Rotation:
    """When the current file is done: ``rotate_s`` after its start, at ``rotate_mb``; 0: never."""

    rotate_s: float = 0.0
    rotate_mb: float = 0.0

    @property
    def on(self) -> bool:
        return self.rotate_s > 0 or self.rotate_mb > 0

    def due(self, age_s: float, size: int) -> str:
        """Why a file ``age_s`` old holding ``size`` bytes is done, or "" while it is not."""
        if self.rotate_s > 0 and age_s >= self.rotate_s:
            return f"after {self.rotate_s:g} s"
        if self.rotate_mb > 0 and size >= self.rotate_mb * 1e6:
            return f"at {self.rotate_mb:g} MB"
        return ""


class Series:
    """The files of one recording, at most one open at a time (``writer``; None between
    files, e.g. while the disk is full). Each file starts with the messages ``carry``
    was given (the robots' info), so it stands alone: ``sonibus info``, ``replay`` and
    ``export`` read any one of them; its metadata names the file before it."""

    def __init__(self, pattern: str, rotation: Rotation, metadata: dict[str, str], flush_s: float) -> None:
        self.names, self.rotation, self.metadata, self.flush_s = Names(pattern), rotation, metadata, flush_s
        self.writer: RecordingWriter | None = None
        self.path = ""          # the file being written, or the last one
        self.paths: list[str] = []  # every file started, in order
        self.closed_bytes = 0   # bytes of the files closed
        self._timed = TIME in pattern  # a timed name never replaces a file (-2...); a fixed one is the node's call
        self._started = 0.0, 0.0  # the current file's start: epoch s, monotonic s
        self._carried: dict[str, dict[str, Any]] = {}
        self._base: dict[str, int] = {}

    def first(self, now: float) -> str:
        """The name the first file will have (for checks before it is opened)."""
        return self.names.at(now, self._taken)

    def open(self, log_ns: int, counters: dict[str, int]) -> int:
        """Start the next file at ``log_ns`` (ns since the epoch), its carried messages first
        (how many is returned); ``counters`` now, for the file's own stats at ``close``.
        ``OSError`` or ``WriteError`` if it cannot be written."""
        now = log_ns / 1e9
        path = self.names.at(now, self._taken)
        folder = os.path.dirname(path)
        if folder:
            os.makedirs(folder, exist_ok=True)
        metadata = {**self.metadata, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(now)),
                    "part": str(len(self.paths) + 1), "previous": os.path.basename(self.path)}
        writer = RecordingWriter(path, metadata, flush_s=self.flush_s)
        self.writer, self.path, self._started, self._base = writer, path, (now, time.monotonic()), dict(counters)
        self.paths.append(path)
        carried = 0
        for key, message in self._carried.items():
            try:
                writer.write(key, log_ns, message)
                carried += 1
            except BadRecord:  # (it was refused when it came as well)
                continue
        return carried

    def carry(self, key: str, message: dict[str, Any]) -> None:
        """Write ``message`` again at the start of every file to come (the latest of its key)."""
        self._carried[key] = message

    def due(self) -> str:
        """Why the current file is done (``Rotation``), or "" while it is not, or none is open."""
        if self.writer is None or not self.rotation.on or int(time.time()) == int(self._started[0]):
            return ""  # (never twice in one second: the next file would have the same name)
        return self.rotation.due(time.monotonic() - self._started[1], self.writer.size)

    def close(self, counters: dict[str, int]) -> None:
        """Finish the current file, with what ``counters`` counted while it was open as its
        stats; ``WriteError`` if it cannot be (it is then only closed: ``sonibus recover``)."""
        writer, self.writer = self.writer, None
        if writer is None:
            return
        try:
            writer.close({k: v - self._base.get(k, 0) for k, v in counters.items()})
        finally:
            with contextlib.suppress(OSError):
                self.closed_bytes += os.path.getsize(writer.path)

    @property
    def files(self) -> int:
        return len(self.paths)

    @property
    def bytes(self) -> int:
        """Bytes of every file so far."""
        return self.closed_bytes + (self.writer.size if self.writer is not None else 0)

    def _taken(self, path: str) -> bool:
        """A name to pass over: one that is there, but the first file of a fixed name (the node
        refuses it there, or replaces it: ``overwrite``)."""
        return (self._timed or bool(self.paths)) and os.path.exists(path)
