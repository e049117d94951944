"""``Recording``: an MCAP file made by the recorder, checked on open and read
message by message (never whole into memory).

A file that is cut short, or whose last chunk is torn (the place a writer that
failed would leave damage), is refused on open with one line that says to run
``sonibus recover``; damage met later while reading is a ``RecordingError`` too.
``recover`` keeps every complete chunk, and of a damaged chunk the records
before the damage.

>>> import os, tempfile
>>> from sonibus.adapters.recorder.writer import RecordingWriter
>>> path = os.path.join(tempfile.mkdtemp(), "doc.mcap")
>>> with RecordingWriter(path) as out:
...     for seq in range(3):
...         out.write("pepper/joints/HeadYaw", (10 + seq) * 10**7, {"t": 0.1 + seq / 100, "seq": seq, "v": 0.5})
>>> with Recording(path) as recording:
...     print(recording.keys, round(recording.duration_s, 3))
...     print([m.data["seq"] for m in recording.messages()])
['pepper/joints/HeadYaw'] 0.02
[0, 1, 2]
"""

from __future__ import annotations

import io
import os
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, BinaryIO

import zenoh
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Metadata, Schema
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader, get_chunk_data_stream

from sonibus.bus import keys
from sonibus.bus.errors import SonibusError

from . import lock
from .channels import AUDIO_ENCODING, MESSAGE_ENCODING, from_data, is_view
from .writer import METADATA_RECORDING, BadRecord, RecordingWriter

MAGIC = b"\x89MCAP0\r\n"
MESSAGE_HEADER = 22  # channel id, sequence, log time, publish time: the bytes of a message record before its data
DAMAGE = (McapError, ValueError, EOFError, MemoryError, OverflowError, struct.error)  # a damaged file, in the reader


class RecordingError(SonibusError):
    """A file that is not a usable recording; the message says why and what to do."""


class StillRecording(RecordingError):
    """A file a recorder is writing now (it holds the file's lock, ``lock.py``): whole
    once it is closed, not torn."""

    def __init__(self, path: str, size: int) -> None:
        super().__init__(f"{path} is being written: a recorder that is running holds it ({size / 1e6:.2f} MB so "
                         "far); it can be read once the recorder closes it (at its next file, or when it stops) — "
                         f"'sonibus recover {path} -o COPY.mcap' copies what it holds so far")
        self.path, self.size = path, size


@dataclass(frozen=True)
class Message:
    """One recorded message: its key, when the recorder got it (``log_ns``), when
    it was acquired (``publish_ns``, from its ``t``), and the message itself."""

    key: str
    log_ns: int
    publish_ns: int
    data: dict[str, Any]


class Recording:
    """An MCAP recording, opened and checked: ``RecordingError`` if it is not one."""

    def __init__(self, path: str) -> None:
        self.path = path
        _check_file(path)
        self._file: BinaryIO = open(path, "rb")  # noqa: SIM115 — closed by close()
        try:
            self._reader = SeekingReader(self._file, validate_crcs=True)
            summary = self._reader.get_summary()
            if summary is not None and summary.chunk_indexes:  # where a writer that failed would have left damage
                last = max(summary.chunk_indexes, key=lambda index: index.chunk_start_offset)
                self._file.seek(last.chunk_start_offset)
                for _ in _chunk_records(_read_chunk(self._file.read(last.chunk_length))):
                    pass
        except DAMAGE as exc:
            self._file.close()
            raise RecordingError(f"{path} is damaged ({_why(exc)}); {_RECOVER.format(path=path)}") from None
        if summary is None or summary.statistics is None:
            self._file.close()
            raise RecordingError(f"{path} has no summary; {_RECOVER.format(path=path)}")
        stats = summary.statistics
        if stats.message_count == 0:
            self._file.close()
            raise RecordingError(f"{path} is an empty recording: it holds no messages")
        self.start_ns, self.end_ns = stats.message_start_time, stats.message_end_time
        self.message_count = stats.message_count
        self._channels: dict[int, Channel] = summary.channels
        self.counts = {c.topic: stats.channel_message_counts.get(cid, 0) for cid, c in summary.channels.items()}
        self.metadata = {m.name: dict(m.metadata) for m in self._reader.iter_metadata()}

    @property
    def keys(self) -> list[str]:
        """The bus keys recorded (what replay, export and plot read); not the views."""
        return sorted(k for k, n in self.counts.items() if n and not is_view(k))

    @property
    def views(self) -> list[str]:
        """The channels the recorder added for Foxglove (``channels.VIEWS``)."""
        return sorted(k for k, n in self.counts.items() if n and is_view(k))

    @property
    def robots(self) -> list[str]:
        return sorted({k.partition("/")[0] for k in self.keys})

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9

    def rate_hz(self, key: str) -> float:
        """Messages per second on ``key`` over the whole recording."""
        return self.counts.get(key, 0) / self.duration_s if self.duration_s > 0 else 0.0

    def matching(self, patterns: Sequence[str]) -> list[str]:
        """The recorded keys that any of ``patterns`` selects; ``RecordingError`` if none does."""
        wanted = [zenoh.KeyExpr(keys.expr(p)) for p in patterns]
        found = [k for k in self.keys if any(w.intersects(zenoh.KeyExpr(k)) for w in wanted)]
        if not found:
            shown = ", ".join(self.keys[:8]) + (", ..." if len(self.keys) > 8 else "")
            raise RecordingError(f"no key in {self.path} matches {' '.join(patterns)} — it holds {shown}")
        return found

    def messages(self, keys: Sequence[str] | None = None, start_s: float | None = None,
                 end_s: float | None = None) -> Iterator[Message]:
        """Messages in the order they were recorded, optionally only ``keys`` and
        only between ``start_s`` and ``end_s`` seconds from the start."""
        start = self.start_ns + int(start_s * 1e9) if start_s is not None else None
        end = self.start_ns + int(end_s * 1e9) if end_s is not None else None
        found = self._reader.iter_messages(topics=keys, starting_at=start, ending_at=end, log_time_order=False)
        while True:
            try:
                _, channel, message = next(found)
                yield _message(channel, message)
            except StopIteration:
                return
            except DAMAGE as exc:
                raise RecordingError(f"{self.path} is damaged ({_why(exc)}); {_RECOVER.format(path=self.path)}") \
                    from None

    def infos(self) -> dict[str, dict[str, Any]]:
        """The last recorded ``<robot>/info`` of each robot."""
        found = {}
        info_keys = [k for k in self.keys if k.endswith("/info")]
        if info_keys:
            for message in self.messages(info_keys):
                found[message.key.partition("/")[0]] = message.data
        return found

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_RECOVER = ("it was not closed cleanly (a killed recorder, a full disk, an unfinished copy); "
            "'sonibus recover {path}' keeps what it holds up to its last complete chunk")


def _check_file(path: str) -> None:
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(len(MAGIC))
            f.seek(max(0, size - len(MAGIC)))
            tail = f.read(len(MAGIC))
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    if size == 0:
        raise RecordingError(f"{path} is empty (0 bytes), not a recording")
    if not MAGIC.startswith(head):  # (a file cut inside its magic is truncated, not foreign)
        raise RecordingError(f"{path} is not an MCAP file (it starts with {head[:8]!r})")
    if tail != MAGIC or size < 2 * len(MAGIC):
        if lock.held(path):
            raise StillRecording(path, size)
        raise RecordingError(f"{path} is truncated: " + _RECOVER.format(path=path))


def head(path: str) -> dict[str, str]:
    """The ``sonibus.recording`` metadata at the start of ``path`` (who writes it, since
    when), read without the summary a file being written does not have yet; {} if none."""
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f, skip_magic=False, emit_chunks=True).records:
                if isinstance(record, Metadata) and record.name == METADATA_RECORDING:
                    return dict(record.metadata)
                if isinstance(record, Chunk):
                    break
    except (OSError, *DAMAGE):
        pass
    return {}


def _message(channel: Channel, message: McapMessage) -> Message:
    if channel.message_encoding not in (MESSAGE_ENCODING, AUDIO_ENCODING):
        raise RecordingError(f"channel {channel.topic} is {channel.message_encoding}, not {MESSAGE_ENCODING} "
                             f"or {AUDIO_ENCODING}: not a sonibus recording")
    return Message(channel.topic, message.log_time, message.publish_time,
                   from_data(channel.message_encoding, message.data))


def _why(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:100]}" if text else type(exc).__name__


def _read_chunk(data: bytes) -> Chunk:
    """The chunk record held whole in ``data``."""
    record = next(StreamReader(io.BytesIO(data), skip_magic=True, emit_chunks=True).records)
    if not isinstance(record, Chunk):
        raise ValueError(f"a {type(record).__name__} record where a chunk should be")
    return record


def _chunk_records(chunk: Chunk) -> Iterator[Channel | Schema | McapMessage]:
    """The records of ``chunk``, each checked to fill its stated length exactly (the
    library's reader lets a torn record swallow the rest of its chunk); ``ValueError``
    at the first that does not."""
    stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    while stream.count < size:
        opcode, length = stream.read1(), stream.read8()
        end = stream.count + length
        if end > size or (opcode == Opcode.MESSAGE and length < MESSAGE_HEADER):
            raise ValueError(f"a torn record at byte {stream.count} of a chunk")
        record: Channel | Schema | McapMessage | None = None
        if opcode == Opcode.MESSAGE:
            record = McapMessage.read(stream, length)
        elif opcode == Opcode.CHANNEL:
            record = Channel.read(stream)
        elif opcode == Opcode.SCHEMA:
            record = Schema.read(stream)
        else:
            stream.read(length)
        if stream.count != end:
            raise ValueError(f"a torn record at byte {stream.count} of a chunk")
        if record is not None:
            yield record


def recover(path: str, out: str) -> int:
    """Copy every message of the damaged recording ``path`` that can be read into a
    new, complete recording ``out``; returns how many."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MAGIC))
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    if not MAGIC.startswith(head):
        raise RecordingError(f"{path} is not an MCAP file (it starts with {head[:8]!r})")
    channels: dict[int, Channel] = {}
    kept = 0
    with open(path, "rb") as f, RecordingWriter(out) as writer:
        try:
            for record in _records(f):
                if isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, McapMessage) and record.channel_id in channels:
                    found = _message(channels[record.channel_id], record)
                    try:
                        writer.write(found.key, found.log_ns, found.data)
                    except BadRecord:  # (from an older recorder): the rest is kept
                        continue
                    kept += 1
                elif isinstance(record, Metadata) and record.name == METADATA_RECORDING:
                    writer.add_metadata(record.name, dict(record.metadata))
        except DAMAGE:
            pass  # the damaged end: everything before it is kept
    if kept == 0:
        os.unlink(out)
        raise RecordingError(f"{path} holds no complete chunk: nothing to recover")
    return kept


def _records(f: BinaryIO) -> Iterator[Any]:
    """The records of an MCAP stream in order, a chunk's one by one, up to the first
    damaged record (raised: a ``DAMAGE`` exception)."""
    for record in StreamReader(f, skip_magic=False, emit_chunks=True).records:
        if isinstance(record, Chunk):
            yield from _chunk_records(record)
        else:
            yield record
