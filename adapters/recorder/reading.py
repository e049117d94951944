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

import math
import os
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, BinaryIO

import zenoh
from mcap.records import Channel, Chunk, ChunkIndex, Metadata
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader

from sonibus.bus import keys
from sonibus.bus.errors import SonibusError
from sonibus.bus.framing import derived_samples, frame_samples
from sonibus.bus.keys import Key
from sonibus.bus.messages import SECTIONS, BadMessage, Gate, Limits

from . import lock
from .bounded import (
    DAMAGE,
    MAX_CHANNELS,
    MAX_RECORD,
    MAX_TOPIC,
    ChunkError,
    NotAsIndexed,
    check_sizes,
    chunk_records,
    expand,
    read_chunk,
    read_record,
    read_summary,
    records,
)
from .channels import AUDIO_ENCODING, MESSAGE_ENCODING, from_data, is_view
from .writer import METADATA_RECORDING, METADATA_STATS

MAGIC = b"\x89MCAP0\r\n"
METADATA = (METADATA_RECORDING, METADATA_STATS)  # the metadata records read (a file may hold any number)


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
    """An MCAP recording, opened and checked: ``RecordingError`` if it is not one.

    Each message read is checked like one on the bus (``bus/messages.py``'s gate: a
    file from a stranger may hold anything); one that fails, or a chunk that cannot be
    read, is skipped and counted in ``skipped`` (``problems()`` says what)."""

    def __init__(self, path: str) -> None:
        self.path = path
        size = _check_file(path)
        self._file: BinaryIO = open(path, "rb")  # noqa: SIM115 — closed by close()
        try:
            self._open(size)
        except BaseException:
            self._file.close()
            raise
        self.checks = Checks(path, data=set(self._frames))

    @property
    def skipped(self) -> dict[str, int]:
        """Messages and chunks skipped so far (``Checks``)."""
        return self.checks.skipped

    def problems(self) -> str:
        """What was skipped so far, in a line ("" if nothing was)."""
        return self.checks.problems()

    def _open(self, size: int) -> None:
        path = self.path
        try:
            summary = read_summary(self._file)
            if summary is not None:
                check_sizes(summary, size)
        except ChunkError as exc:  # (what the index says: recover, which reads every chunk, cannot help)
            raise RecordingError(f"{path} cannot be read: {exc}") from None
        except DAMAGE as exc:
            raise RecordingError(f"{path} is damaged ({why(exc)}); {_RECOVER.format(path=path)}") from None
        try:
            if summary is not None:
                self._indexes = sorted(summary.chunk_indexes, key=lambda index: index.chunk_start_offset)
                if self._indexes:  # the last chunk: where a writer that failed would have left damage
                    last = self._indexes[-1]
                    for _ in chunk_records(expand(read_chunk(self._file, last), last.chunk_start_offset)):
                        pass
        except NotAsIndexed as exc:
            raise RecordingError(f"{path} cannot be read: {exc}; 'sonibus recover {path}' reads its chunks, "
                                 "not its index") from None
        except ChunkError as exc:
            many = summary is not None and len(summary.chunk_indexes) > 1
            raise RecordingError(f"{path} cannot be read: {exc}" + (
                f"; 'sonibus recover {path}' keeps its other chunks" if many else "")) from None
        except DAMAGE as exc:
            raise RecordingError(f"{path} is damaged ({why(exc)}); {_RECOVER.format(path=path)}") from None
        if summary is None or summary.statistics is None:
            raise RecordingError(f"{path} has no summary; {_RECOVER.format(path=path)}")
        if len(summary.channels) > MAX_CHANNELS:
            raise RecordingError(f"{path} holds {len(summary.channels)} channels, more than sonibus reads "
                                 f"({MAX_CHANNELS}, as many as its recorder writes): not a recording of robots")
        for channel in summary.channels.values():
            if len(channel.topic) > MAX_TOPIC:
                raise RecordingError(f"{path} holds a channel named by {len(channel.topic)} characters "
                                     f"('{channel.topic[:40]}...'), more than a key may ({MAX_TOPIC})")
        stats = summary.statistics
        if stats.message_count == 0:
            raise RecordingError(f"{path} is an empty recording: it holds no messages")
        self.start_ns, self.end_ns = stats.message_start_time, stats.message_end_time
        self._message_count = stats.message_count
        # channels of a data key or a view: a message on any other is skipped (keys are what readers take apart)
        self._channels: dict[int, Channel] = {cid: c for cid, c in summary.channels.items()
                                              if is_view(c.topic) or data_key(c.topic)}
        self._counts = {c.topic: stats.channel_message_counts.get(cid, 0) for cid, c in self._channels.items()}
        # frames (one message a frame) read as the samples of their keys: derived frames (<robot>/derived), and
        # a robot's frames (<robot>/frame) when the file holds no joint key of it (else they are Foxglove's view of
        # those joints, as the recorder wrote them before issue 35)
        self._frames = _frames(self._counts)
        self._derived_frames = {f for f, prefix in self._frames.items() if prefix.endswith("/derived/")}
        self._expanded = not self._frames
        self.metadata: dict[str, dict[str, str]] = {}
        try:
            for index in summary.metadata_indexes:
                if index.name in METADATA and index.name not in self.metadata:
                    record = read_record(self._file, index.offset)
                    if isinstance(record, Metadata):
                        self.metadata[record.name] = dict(record.metadata)
        except DAMAGE as exc:
            raise RecordingError(f"{path} is damaged ({why(exc)}); {_RECOVER.format(path=path)}") from None

    @property
    def counts(self) -> dict[str, int]:
        """Messages per key recorded; a frame's joints and a derived frame's values counted on
        their own keys, as if each had been recorded on its key (as the recorder did before)."""
        if not self._expanded:
            found: dict[str, int] = {}
            for message in self._raw(list(self._frames)):
                prefix = self._frames[message.key]
                for name in message.data["names"]:
                    key = prefix + name
                    if key in found or len(found) < MAX_CHANNELS:  # (names come from the file)
                        found[key] = found.get(key, 0) + 1
            frames = sum(n for k, n in self._counts.items() if k in self._frames)
            self._message_count += sum(found.values()) - frames
            self._counts = {k: n for k, n in self._counts.items() if k not in self._frames} | found
            self._expanded = True
        return self._counts

    @property
    def message_count(self) -> int:
        """Messages in the file, as ``messages()`` gives them (a derived frame: its values)."""
        _ = self.counts
        return self._message_count

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

    @property
    def derived_frames(self) -> set[str]:
        """The channels of derived frames (``pepper/derived``): what ``messages(frames=True)`` gives whole."""
        return set(self._derived_frames)

    @property
    def frames(self) -> set[str]:
        """The channels read as the samples of their keys (``pepper/frame``: its joints;
        ``pepper/derived``: its values): what ``messages(frames=True)`` gives whole."""
        return set(self._frames)

    def messages(self, keys: Sequence[str] | None = None, start_s: float | None = None,
                 end_s: float | None = None, frames: bool = False) -> Iterator[Message]:
        """Messages in the order they were recorded, optionally only ``keys`` and
        only between ``start_s`` and ``end_s`` seconds from the start; what cannot be
        read is skipped and counted (``skipped``). A frame comes as the samples of its
        keys (``pepper/joints/HeadYaw``, ``pepper/derived/qom/Body``), in its order, as a
        recording made before frames were recorded whole holds them; with ``frames``
        (replay) it comes whole, holding only the joints or values of ``keys``; and whole when
        ``keys`` names its channel (``pepper/frame``, as Foxglove's view of a file of before)."""
        if not self._frames:
            yield from self._raw(keys, start_s, end_s)
            return
        wanted = None if keys is None else set(keys)
        chosen = {f for f, prefix in self._frames.items()
                  if wanted is None or any(k.startswith(prefix) for k in wanted)}
        for message in self._raw(None if wanted is None else [*wanted, *chosen], start_s, end_s):
            prefix = self._frames.get(message.key)
            if prefix is None or (wanted is not None and message.key in wanted):  # (asked for by its own name)
                yield message
                continue
            data = message.data
            every = derived_samples(data) if prefix.endswith("/derived/") else frame_samples(data)
            if not frames:
                yield from (Message(prefix + name, message.log_ns, message.publish_ns, sample)
                            for name, sample in every if wanted is None or prefix + name in wanted)
                continue
            index = [i for i, name in enumerate(data["names"]) if wanted is None or prefix + name in wanted]
            if len(index) == len(data["names"]):
                yield message
            elif index:
                yield Message(message.key, message.log_ns, message.publish_ns, {
                    q: [v[i] for i in index] if q not in ("t", "seq") else v for q, v in data.items()})

    def _raw(self, keys: Sequence[str] | None = None, start_s: float | None = None,
             end_s: float | None = None) -> Iterator[Message]:
        """``messages`` as recorded: a frame whole."""
        start = self.start_ns + int(start_s * 1e9) if start_s is not None else 0
        end = self.start_ns + int(end_s * 1e9) if end_s is not None else None
        wanted = {cid for cid, c in self._channels.items() if keys is None or c.topic in set(keys)}
        if not self._indexes:  # (messages outside chunks: read in order, chunk by chunk)
            yield from self._unindexed(wanted, start, end)
            return
        for index in self._indexes:
            if index.message_end_time < start or (end is not None and index.message_start_time >= end):
                continue
            yield from self._chunk(index, wanted, start, end)

    def _chunk(self, index: ChunkIndex, wanted: set[int], start: int = 0, end: int | None = None) -> Iterator[Message]:
        """The messages of the chunk ``index`` points to on channels ``wanted``, logged in [start, end)."""
        if index.message_index_offsets and wanted.isdisjoint(index.message_index_offsets):
            return
        at = index.chunk_start_offset
        try:
            data = expand(read_chunk(self._file, index), at)
            for n, record in enumerate(chunk_records(data)):
                if isinstance(record, McapMessage) and record.channel_id in wanted \
                        and start <= record.log_time and (end is None or record.log_time < end):
                    found = self.checks.message(self._channels[record.channel_id], record, (at, n))
                    if found is not None:
                        yield found
        except ChunkError as exc:
            self.checks.skip("chunks", str(exc), at)
        except DAMAGE as exc:  # (a record torn inside a chunk: those before it were read)
            self.checks.skip("chunks", f"the chunk at byte {at}: {why(exc)}", at)

    def _unindexed(self, wanted: set[int], start: int, end: int | None) -> Iterator[Message]:
        bad: list[ChunkError] = []
        with open(self.path, "rb") as f:  # (its own: two readings may take turns)
            try:
                for record in records(f, bad):
                    while bad:
                        self.checks.skip("chunks", str(bad.pop()))
                    if isinstance(record, McapMessage) and record.channel_id in wanted \
                            and start <= record.log_time and (end is None or record.log_time < end):
                        found = self.checks.message(self._channels[record.channel_id], record)
                        if found is not None:
                            yield found
            except DAMAGE as exc:
                raise RecordingError(f"{self.path} is damaged ({why(exc)}); {_RECOVER.format(path=self.path)}") \
                    from None

    def infos(self) -> dict[str, dict[str, Any]]:
        """The last recorded ``<robot>/info`` of each robot (read from the last chunks
        that hold one: a file of a million infos took ``info`` 50 s)."""
        found = {}
        for key in (k for k in self.keys if k.endswith("/info")):
            last = self._last(key)
            if last is not None:
                found[key.partition("/")[0]] = last.data
        return found

    def _last(self, key: str) -> Message | None:
        """The last message on ``key`` that passes the checks, read backwards a chunk at a time."""
        wanted = {cid for cid, c in self._channels.items() if c.topic == key}
        last = None
        for found in (self._chunk(index, wanted) for index in reversed(self._indexes)) if self._indexes \
                else [self.messages([key])]:
            for last in found:  # noqa: B007 (the last one is wanted)
                pass
            if last is not None:
                return last
        return None

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Checks:
    """Each message read from a file checked like one on the bus (``bus/messages.py``'s
    gate; a view only to be a map): a file from a stranger may hold anything. What
    fails is skipped and counted in ``skipped``, as is a chunk that cannot be read."""

    REMEMBERED = 1 << 16  # places skipped that are remembered, not counted twice (replay reads a file again)

    def __init__(self, path: str, data: Collection[str] = ()) -> None:
        self.path = path
        self.data = data  # channels named like a view that hold bus data (a robot's frames: ``_frames``)
        self.skipped: dict[str, int] = {"messages": 0, "chunks": 0}
        self._first: dict[str, str] = {}  # what, of each kind, was skipped first
        self._seen: set[object] = set()
        self._keys: dict[str, Key] = {}  # each channel's topic taken apart (a file's channels: MAX_CHANNELS)
        # (a recording's t are old, and its bus may have allowed larger payloads)
        self._gate = Gate(Limits(max_future_s=math.inf, max_payload=1 << 30, max_info_payload=1 << 30))

    def message(self, channel: Channel, message: McapMessage, where: object = None) -> Message | None:
        """The message, checked; None, counted, if it fails (once for each ``where``, its place in the file)."""
        if channel.message_encoding not in (MESSAGE_ENCODING, AUDIO_ENCODING):
            raise RecordingError(f"channel {channel.topic} is {channel.message_encoding}, not {MESSAGE_ENCODING} "
                                 f"or {AUDIO_ENCODING}: not a sonibus recording")
        try:
            data = from_data(channel.message_encoding, message.data)
            if data.__class__ is not dict:
                raise BadMessage(f"a {type(data).__name__}, not a map")
            if not is_view(channel.topic) or channel.topic in self.data:
                key = self._keys.get(channel.topic) or self._keys.setdefault(channel.topic, Key.parse(channel.topic))
                SECTIONS[key.section].check(self._gate, key, data)
        except (BadMessage, KeyError, TypeError, ValueError, RecursionError, OverflowError) as exc:
            self.skip("messages", f"{channel.topic[:80]}: {why(exc)}", where)
            return None
        return Message(channel.topic, message.log_time, message.publish_time, data)

    def skip(self, kind: str, why: str, where: object = None) -> None:
        """Count one ``kind`` skipped, unless what is at ``where`` was (None: always count)."""
        if where is not None:
            if (kind, where) in self._seen:
                return
            if len(self._seen) < self.REMEMBERED:
                self._seen.add((kind, where))
        self.skipped[kind] += 1
        self._first.setdefault(kind, why)

    def problems(self) -> str:
        """What was skipped so far, in a line ("" if nothing was)."""
        said = [f"{n} {kind[:-1] if n == 1 else kind} (the first: {self._first[kind]})"
                for kind, n in self.skipped.items() if n]
        return f"{self.path}: skipped " + " and ".join(said) if said else ""


_RECOVER = ("it was not closed cleanly (a killed recorder, a full disk, an unfinished copy); "
            "'sonibus recover {path}' keeps what it holds up to its last complete chunk")


def _check_file(path: str) -> int:
    """The size of ``path``, an MCAP file that is whole; ``RecordingError`` if it is not."""
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
    return size


def head(path: str) -> dict[str, str]:
    """The ``sonibus.recording`` metadata at the start of ``path`` (who writes it, since
    when), read without the summary a file being written does not have yet; {} if none."""
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f, skip_magic=False, emit_chunks=True, record_size_limit=MAX_RECORD).records:
                if isinstance(record, Metadata) and record.name == METADATA_RECORDING:
                    return dict(record.metadata)
                if isinstance(record, Chunk):
                    break
    except (OSError, *DAMAGE):
        pass
    return {}


def _frames(counts: dict[str, int]) -> dict[str, str]:
    """Of a file's channels (``counts``: messages on each), those whose messages are frames read as
    the samples of their keys, each with its keys' prefix: every derived frame (``pepper/derived`` →
    ``pepper/derived/``), and a robot's frames (``pepper/frame`` → ``pepper/joints/``) unless the file
    holds joint keys of that robot: a recorder before issue 35 wrote a message per joint, and the
    frames beside them were Foxglove's view of the same samples."""
    # (a joint channel counts whether or not the file's statistics give it messages: a writer may leave its
    # counts out, and the frames beside an old file's joints would then be read as joints a second time)
    per_joint = {k.partition("/")[0] for k in counts if k.partition("/")[2].startswith("joints/")}
    framed = {k: k + "/" for k in counts if keys.is_derived_frame(k)}
    return framed | {k: keys.joint(k.partition("/")[0], "") for k in counts
                     if keys.is_frame(k) and k.partition("/")[0] not in per_joint}


def data_key(topic: str) -> bool:
    """A topic that is a bus key (one Zenoh takes: replay puts it back on the bus) of one of the key
    space's sections."""
    try:
        zenoh.KeyExpr(topic)
        return Key.parse(topic).section in SECTIONS
    except Exception:  # (zenoh's own error for what is no key: "a*b", "a//b", "$x")
        return False


def why(exc: BaseException) -> str:
    if isinstance(exc, BadMessage | ChunkError):
        return " ".join(str(exc).split())[:160]
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:100]}" if text else type(exc).__name__
