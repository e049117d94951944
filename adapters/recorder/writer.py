"""``RecordingWriter``: bus messages into an MCAP file, one channel per key.

Chunks are closed every ``flush_s`` seconds (and at ``chunk_bytes``), written
through and fsync'ed, so a recorder killed without warning leaves a file that
holds everything up to the last closed chunk; ``close()`` adds the summary and
index that make a file seekable.

Each message is checked whole before any byte of it reaches the file: one
that cannot be written (not strict JSON: bytes, NaN; a log time MCAP cannot
hold; audio chunks are msgpack, ``channels.encoding_of``) raises
``BadRecord`` and leaves nothing behind. A failing disk raises
``WriteError`` naming the file; the file is then closed as it is (readable up
to its last complete chunk with ``sonibus recover``), never finished over a
torn chunk.

>>> import os, tempfile
>>> path = os.path.join(tempfile.mkdtemp(), "doc.mcap")
>>> with RecordingWriter(path) as out:
...     out.write("pepper/joints/HeadYaw", 1_700_000_000_000_000_000, {"t": 1.7e9, "seq": 0, "v": 0.1})
>>> out.messages
1
>>> with RecordingWriter(path) as out:
...     try:
...         out.write("pepper/events/behavior", 1_700_000_000_000_000_000, {"t": 1.7e9, "kind": "x", "name": b"x"})
...     except BadRecord as exc:
...         print(exc)
not strict JSON: Object of type bytes is not JSON serializable
"""

from __future__ import annotations

import contextlib
import os
import time
from importlib.metadata import version
from typing import Any, BinaryIO

from mcap.writer import CompressionType, Writer

from sonibus.bus.errors import SonibusError

from . import index, lock
from .bounded import MAX_CHANNELS, MAX_TOPIC
from .channels import AUDIO_ENCODING, PROFILE, SCHEMA_ENCODING, channel_schema, encoding_of, to_data

METADATA_RECORDING = "sonibus.recording"
METADATA_STATS = "sonibus.stats"
TIME_LIMIT_NS = 1 << 64        # MCAP times are uint64 ns since the epoch
MAX_CLOCK_OFFSET_S = 60.0      # a t further than this from the log time is not a publish time (a clock gone wrong)


class BadRecord(ValueError):
    """A message the writer will not write; nothing of it reached the file."""


class WriteError(SonibusError):
    """The file cannot be written (disk full, I/O error); the message names it."""


class RecordingWriter:
    """Writes messages as they come; ``close()`` (or leaving ``with``) finishes the file."""

    def __init__(self, path: str, metadata: dict[str, str] | None = None, flush_s: float = 1.0,
                 chunk_bytes: int = 1 << 20) -> None:
        self.path = path
        self.flush_s = flush_s
        self.messages = 0
        self.closed = False
        self.failed = False  # a WriteError happened: the file is only closed, never finished
        self._file: BinaryIO = self._do(_open_locked, path)
        self._writer = Writer(self._file, chunk_size=chunk_bytes, compression=CompressionType.ZSTD)
        # its chunk indexes on disk until close: in memory they grew 15 MB an hour for as long as the file
        self._indexes = self._do(index.spill, self._writer, os.path.dirname(os.path.abspath(path)))
        self._do(self._writer.start, profile=PROFILE, library=f"sonibus {version('sonibus')}")
        if metadata is not None:
            self.add_metadata(METADATA_RECORDING, metadata)
        self._do(self._file.flush)  # (the head is on disk at once: `sonibus info` says who writes the file)
        self._schemas: dict[str | None, int] = {None: 0}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self._last_flush = time.monotonic()

    def write(self, key: str, log_ns: int, message: dict[str, Any]) -> None:
        """One message received at ``log_ns`` (ns since the epoch); its ``t`` is the
        publish time when it is within ``MAX_CLOCK_OFFSET_S`` of ``log_ns``, else
        ``log_ns`` is. ``BadRecord`` if it cannot be written (nothing is), ``WriteError``
        if the file cannot."""
        refused = self.write_all([(key, message)], log_ns)
        if refused:
            raise refused[0][1]

    def write_all(self, messages: list[tuple[str, dict[str, Any]]], log_ns: int) -> list[tuple[str, BadRecord]]:
        """Several ``(key, message)`` received at ``log_ns`` (a frame's joints and views), each
        as ``write`` writes it, in one go (issue 35: what was paid per message, once); those it
        cannot write are skipped and returned with why, the others written. ``WriteError`` if
        the file cannot be written."""
        if self.closed or self.failed:
            raise WriteError(f"cannot write {self.path}: it is {'closed' if self.closed else 'failed'}")
        if log_ns.__class__ is not int or not 0 <= log_ns < TIME_LIMIT_NS:
            return [(key, BadRecord(f"log time {log_ns!r} is not in 0..2^64 ns")) for key, _ in messages]
        refused: list[tuple[str, BadRecord]] = []
        channels, sequences, add = self._channels, self._sequence, self._writer.add_message
        try:
            for key, message in messages:
                try:
                    data = _data(key, message)
                    channel = channels.get(key)
                    if channel is None:
                        channel = channels[key] = self._new_channel(key)
                except BadRecord as exc:
                    refused.append((key, exc))
                    continue
                sequence = sequences[channel] = (sequences.get(channel, -1) + 1) & 0xFFFFFFFF  # uint32: wraps
                add(channel, log_time=log_ns, data=data, publish_time=_publish_ns(message.get("t"), log_ns),
                    sequence=sequence)
                self.messages += 1
        except OSError as exc:
            self.failed = True
            raise WriteError(f"cannot write {self.path}: {exc.strerror or exc}") from exc
        if time.monotonic() - self._last_flush >= self.flush_s:
            self.flush()
        return refused

    def _new_channel(self, key: str) -> int:
        """The channel of a key not written yet (bounds its readers keep too: bounded.py)."""
        if len(self._channels) >= MAX_CHANNELS:
            raise BadRecord(f"a file holds at most {MAX_CHANNELS} keys; '{key[:80]}' would be one more")
        if len(key) > MAX_TOPIC:
            raise BadRecord(f"a key of {len(key)} characters ('{key[:40]}...'), more than a file's may "
                            f"({MAX_TOPIC})")
        return self._channel(key)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._do(self._writer.add_metadata, name, data)

    def flush(self) -> None:
        """Close the chunk in progress and put it on disk."""
        self._do(self._writer.flush)
        self._do(os.fsync, self._file.fileno())
        self._last_flush = time.monotonic()

    def close(self, stats: dict[str, Any] | None = None) -> None:
        """Write ``stats`` as metadata, the summary and the index; safe to call twice.
        After a ``WriteError`` it only closes the file (see ``abandon``)."""
        if self.closed:
            return
        if self.failed:
            self.abandon()
            return
        self.closed = True
        try:
            if stats:
                self._do(self._writer.add_metadata, METADATA_STATS, {k: str(v) for k, v in stats.items()})
            self._do(self._writer.finish)
            self._do(self._file.flush)
            self._do(os.fsync, self._file.fileno())
        except BaseException:
            self.abandon()
            raise
        self._file.close()
        self._drop_indexes()

    def abandon(self) -> None:
        """Close the file as it is, after a failure: what reached the disk stays a
        prefix of the recording (``sonibus recover`` keeps its complete chunks);
        never raises."""
        self.closed = True
        with contextlib.suppress(OSError, ValueError):
            self._file.close()  # (it may still write what it buffers: the next bytes, in order)
        self._drop_indexes()

    def _drop_indexes(self) -> None:
        if self._indexes is not None:
            with contextlib.suppress(OSError):
                self._indexes.close()

    def _do(self, action: Any, *args: Any, **kwargs: Any) -> Any:
        """``action`` on the file; an ``OSError`` becomes a ``WriteError`` naming it."""
        try:
            return action(*args, **kwargs)
        except OSError as exc:
            self.failed = True
            raise WriteError(f"cannot write {self.path}: {exc.strerror or exc}") from exc

    @property
    def size(self) -> int:
        """Bytes on disk so far."""
        return self._file.tell() if not self.closed else os.path.getsize(self.path)

    def _channel(self, key: str) -> int:
        schema = channel_schema(key)
        name = schema[0] if schema is not None else None
        schema_id = self._schemas.get(name)
        if schema_id is None and schema is not None:
            schema_id = self._schemas[name] = self._writer.register_schema(name, SCHEMA_ENCODING, schema[1])
        return self._writer.register_channel(key, encoding_of(key), schema_id or 0)

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _open_locked(path: str) -> BinaryIO:
    """``path`` opened for writing from its start, under the writer's lock (``lock.py``),
    taken before the file is emptied: a file another recorder writes is left alone."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        if not lock.hold(fd):
            raise WriteError(f"cannot write {path}: another recorder is writing it (it holds the file's lock) — "
                             "give this one another path")
        os.ftruncate(fd, 0)
        return os.fdopen(fd, "wb")
    except BaseException:
        os.close(fd)
        raise


def _data(key: str, message: Any) -> bytes:
    """``message`` as its channel holds it: strict JSON (no bytes, NaN or infinity), or
    msgpack for audio; else ``BadRecord``."""
    if message.__class__ is not dict:
        raise BadRecord(f"not a map but {type(message).__name__}")
    try:
        return to_data(key, message)
    except (TypeError, ValueError, RecursionError) as exc:
        what = "msgpack" if encoding_of(key) == AUDIO_ENCODING else "strict JSON"
        raise BadRecord(f"not {what}: {exc}") from None


def _publish_ns(t: Any, log_ns: int) -> int:
    """``t`` (s since the epoch) in ns when it is a plausible publish time, else ``log_ns``."""
    if t.__class__ not in (int, float):
        return log_ns
    try:
        plausible = abs(t - log_ns / 1e9) <= MAX_CLOCK_OFFSET_S  # (False for NaN and infinity)
    except OverflowError:  # an int no float can hold
        return log_ns
    return max(0, min(int(t * 1e9), TIME_LIMIT_NS - 1)) if plausible else log_ns


def unwritable(path: str) -> str | None:
    """Why a recording cannot be written at ``path`` and what to do, found without
    writing anything; None if it looks writable (opening it is the last word)."""
    if os.path.isdir(path):
        return f"{path} is a folder — name a file in it, e.g. {os.path.join(path, 'show-{time}.mcap')}"
    folder = os.path.dirname(os.path.abspath(path))
    while True:  # up to the first folder that is there: the recorder would create the others
        try:
            os.stat(folder)
            break
        except PermissionError:
            return f"{path} cannot be created: no permission to enter {os.path.dirname(folder)} — " \
                   "choose a folder you can write to"
        except OSError:  # not there, or under a file
            folder = os.path.dirname(folder)
    if not os.path.isdir(folder):
        return f"{path} cannot be created: {folder} is a file, not a folder — choose another folder"
    if os.statvfs(folder).f_flag & os.ST_RDONLY:
        return f"{path} cannot be created: {folder} is on a read-only file system — choose a folder you can write to"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"{path} cannot be created: no permission to write in {folder} — choose a folder you can write to"
    return None
