"""Reading an MCAP file from a stranger within bounds: no record, chunk or summary
is taken at its word.

mcap's own reader trusts a file: it decompresses a chunk whole to whatever size
the chunk declares (zstd) or to whatever it expands to (lz4), and breaks it into a
list of every record it holds. A 98 KB file with one zstd chunk that expands to
3 GiB took every command past 2.5 GB. Here a chunk is decompressed only up to the
size it declares, and only if that is at most ``MAX_CHUNK``; one that expands to
more or less, or whose record disagrees with the file's index, is a ``ChunkError``;
its records are read one by one from the decompressed bytes (``chunk_records``).
The summary is read record by record too (a summary that points into the data
section met a chunk there, which mcap's reader decompressed whole).

>>> import io
>>> from mcap.writer import Writer
>>> out = io.BytesIO()
>>> writer = Writer(out)
>>> writer.start()
>>> channel = writer.register_channel("pepper/joints/HeadYaw", "json", 0)
>>> writer.add_message(channel, log_time=1, data=b"{}", publish_time=1)
>>> writer.finish()
>>> found = read_summary(out)
>>> [(index.uncompressed_size, index.compression) for index in found.chunk_indexes]
[(83, 'zstd')]
>>> [type(r).__name__ for r in chunk_records(expand(read_chunk(out, found.chunk_indexes[0]), 0))]
['Channel', 'Message']
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Iterator
from typing import Any, BinaryIO

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    Footer,
    Message,
    MetadataIndex,
    Schema,
    Statistics,
)
from mcap.stream_reader import StreamReader
from mcap.summary import Summary

MAX_CHUNK = 32 << 20       # bytes a chunk may expand to (the recorder's close at 1 MiB, or every second)
MAX_RECORD = MAX_CHUNK + 4096  # bytes of any record in the file (a chunk's, compressed, or less)
MAX_RATIO = 200            # chunks may expand to at most this many times the file's size, in all (beyond one chunk)
MAX_CHANNELS = 4096        # channels read from one file (a robot's keys are about 60, its views a few more)
MAX_TOPIC = 1024           # characters of a channel's topic (a bus key)
MESSAGE_HEADER = 22        # channel id, sequence, log time, publish time: the bytes of a message record before its data
HEAD = struct.Struct("<BQ")  # a record's opcode and content length
MESSAGE_HEAD = struct.Struct("<HIQQ")  # a message record's channel id, sequence, log time, publish time
FOOTER_SIZE = HEAD.size + 8 + 8 + 4
MAGIC_SIZE = 8
# what a damaged or hostile file raises in mcap's reader and in these readers
DAMAGE = (McapError, ValueError, EOFError, MemoryError, OverflowError, struct.error, UnicodeDecodeError)


class ChunkError(ValueError):
    """A chunk that cannot be read as it says: too large, lying about its size, corrupt."""


class NotAsIndexed(ChunkError):
    """A chunk that is not what the file's index says (``recover`` reads the chunks, not the index)."""


def read_summary(f: BinaryIO) -> Summary | None:
    """The summary section of ``f`` (None if it has none), read record by record,
    none larger than ``MAX_RECORD``; a chunk met there is not opened."""
    _seek(f, f.seek(0, io.SEEK_END) - FOOTER_SIZE - MAGIC_SIZE)  # (a file shorter than a footer: refused)
    footer = next(StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=MAX_RECORD).records)
    if not isinstance(footer, Footer):
        raise McapError(f"expected the footer at the end of the file, found a {type(footer).__name__}")
    if footer.summary_start == 0:
        return None
    _seek(f, footer.summary_start)
    summary = Summary()
    for record in StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=MAX_RECORD).records:
        if isinstance(record, Statistics):
            summary.statistics = record
        elif isinstance(record, Schema):
            summary.schemas[record.id] = record
        elif isinstance(record, Channel):
            summary.channels[record.id] = record
        elif isinstance(record, ChunkIndex):
            summary.chunk_indexes.append(record)
        elif isinstance(record, MetadataIndex):
            summary.metadata_indexes.append(record)
        elif isinstance(record, AttachmentIndex):
            continue
        elif isinstance(record, Footer):
            break
    return summary


def read_record(f: BinaryIO, offset: int) -> Any:
    """The record at ``offset`` of ``f`` (a chunk not opened), at most ``MAX_RECORD`` bytes."""
    _seek(f, offset)
    return next(StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=MAX_RECORD).records)


def _seek(f: BinaryIO, offset: int) -> None:
    """To ``offset`` of ``f``, an offset the file gave: ``McapError`` if it is not in the file."""
    size = f.seek(0, io.SEEK_END)
    if not 0 <= offset < size:
        raise McapError(f"an offset ({offset}) outside the file ({size} bytes)")
    f.seek(offset)


def read_chunk(f: BinaryIO, index: ChunkIndex) -> Chunk:
    """The chunk ``index`` points to, checked against it (``ChunkError`` if they disagree)."""
    chunk = read_record(f, index.chunk_start_offset)
    where = f"the chunk at byte {index.chunk_start_offset}"
    if not isinstance(chunk, Chunk):
        raise NotAsIndexed(f"{where} is a {type(chunk).__name__} record, not a chunk")
    if (chunk.uncompressed_size, chunk.compression, len(chunk.data)) != \
            (index.uncompressed_size, index.compression, index.compressed_size):
        raise NotAsIndexed(f"{where} says it holds {_size(len(chunk.data))} of {chunk.compression or 'raw'} data "
                         f"expanding to {_size(chunk.uncompressed_size)}; the file's index says "
                         f"{_size(index.compressed_size)} of {index.compression or 'raw'} to "
                         f"{_size(index.uncompressed_size)}")
    return chunk


def expand(chunk: Chunk, offset: int) -> bytes:
    """The records of ``chunk`` (found at byte ``offset``), decompressed: never more than
    it declares nor than ``MAX_CHUNK``; ``ChunkError`` if it declares more, expands to
    more or less than it declares, or fails its CRC."""
    where, declared = f"the chunk at byte {offset}", chunk.uncompressed_size
    if declared > MAX_CHUNK:
        raise ChunkError(f"{where} says it expands to {_size(declared)}, more than a chunk may "
                         f"({_size(MAX_CHUNK)}; sonibus's recorder writes chunks of about 1 MiB)")
    try:
        if chunk.compression == "zstd":
            with zstandard.ZstdDecompressor().stream_reader(chunk.data) as reader:
                data = _read_up_to(reader, declared + 1)
        elif chunk.compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=declared + 1)
        elif chunk.compression == "":
            data = chunk.data
        else:
            raise ChunkError(f"{where} is compressed with '{chunk.compression[:40]}': only zstd and lz4 are read")
    except (zstandard.ZstdError, RuntimeError) as exc:  # (lz4 raises RuntimeError for corrupt data)
        raise ChunkError(f"{where} is corrupt ({chunk.compression}: {' '.join(str(exc).split())[:80]})") from None
    if len(data) != declared:
        more = "more than" if len(data) > declared else f"{_size(len(data))}, not"
        raise ChunkError(f"{where} expands to {more} the {_size(declared)} it says")
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        raise ChunkError(f"{where} fails its CRC check")
    return data


def _read_up_to(reader: Any, size: int) -> bytes:
    parts, got = [], 0
    while got < size:
        part = reader.read(size - got)
        if not part:
            break
        parts.append(part)
        got += len(part)
    return b"".join(parts)


def chunk_records(data: bytes) -> Iterator[Channel | Schema | Message]:
    """The records of a chunk's decompressed ``data``, one at a time, each checked to
    fill its stated length exactly (mcap's reader lets a torn record swallow the rest
    of its chunk); ``ValueError`` at the first that does not."""
    size, at = len(data), 0
    while at < size:
        if size - at < HEAD.size:
            raise ValueError(f"a torn record at byte {at} of a chunk")
        opcode, length = HEAD.unpack_from(data, at)
        start = at + HEAD.size
        at = start + length
        if at > size or (opcode == Opcode.MESSAGE and length < MESSAGE_HEADER):
            raise ValueError(f"a torn record at byte {start} of a chunk")
        if opcode == Opcode.MESSAGE:  # (the most of them: read here, three times as fast as mcap's ReadDataStream)
            channel, sequence, log_time, publish_time = MESSAGE_HEAD.unpack_from(data, start)
            yield Message(channel_id=channel, log_time=log_time, data=data[start + MESSAGE_HEADER:at],
                          publish_time=publish_time, sequence=sequence)
        elif opcode in (Opcode.CHANNEL, Opcode.SCHEMA):
            stream = ReadDataStream(io.BytesIO(data[start:at]))
            record = Channel.read(stream) if opcode == Opcode.CHANNEL else Schema.read(stream)
            if stream.count != length:
                raise ValueError(f"a torn record at byte {start} of a chunk")
            yield record


def records(f: BinaryIO, bad_chunk: list[ChunkError]) -> Iterator[Any]:
    """The records of the MCAP file ``f`` in order, a chunk's one by one; a chunk that
    cannot be expanded, or would take what its chunks expand to past ``allowance``, is
    skipped and appended to ``bad_chunk``. Raises a ``DAMAGE`` exception at the first
    damaged record outside a chunk (or inside one, after its records before the damage)."""
    offset, left = 0, allowance(f.seek(0, io.SEEK_END))
    f.seek(0)
    stream = StreamReader(f, skip_magic=False, emit_chunks=True, record_size_limit=MAX_RECORD)
    for record in stream.records:
        if isinstance(record, Chunk):
            try:
                if record.uncompressed_size > left:
                    raise ChunkError(f"the chunk at byte {offset} would take what the file's chunks expand to "
                                     f"past {MAX_RATIO} times its size (a decompression bomb?)")
                left -= record.uncompressed_size
                data = expand(record, offset)
            except ChunkError as exc:
                bad_chunk.append(exc)
            else:
                yield from chunk_records(data)
        else:
            yield record
        offset = f.tell()


def allowance(file_size: int) -> int:
    """Bytes the chunks of a file of ``file_size`` may expand to, in all: ``MAX_RATIO``
    times its size, and 4 MiB more (a short file's chunk may compress better)."""
    return (4 << 20) + MAX_RATIO * file_size


def check_sizes(summary: Summary, file_size: int) -> None:
    """``ChunkError`` if the index says a chunk expands past ``MAX_CHUNK``, or all of
    them past ``allowance`` (a decompression bomb)."""
    total = 0
    for index in summary.chunk_indexes:
        if index.uncompressed_size > MAX_CHUNK:
            raise ChunkError(f"its index says the chunk at byte {index.chunk_start_offset} expands to "
                             f"{_size(index.uncompressed_size)}, more than a chunk may ({_size(MAX_CHUNK)}; "
                             "sonibus's recorder writes chunks of about 1 MiB)")
        total += index.uncompressed_size
    if total > allowance(file_size):
        raise ChunkError(f"its index says its chunks expand to {_size(total)}, {total / max(file_size, 1):.0f} times "
                         f"its size (at most {MAX_RATIO} times: recordings compress about 10 times)")


def _size(count: int) -> str:
    return f"{count / 2**20:.1f} MiB" if count >= 100_000 else f"{count} bytes"
