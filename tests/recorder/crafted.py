"""Hostile recordings, built record by record: what a stranger's file may hold.

``craft`` writes a well-formed MCAP (header, channels, chunks, a summary with
statistics and chunk indexes, footer) from ``Part``s, each of which may lie: a
chunk whose data expands far past what it declares, an index that disagrees
with its chunk, messages that are not JSON objects. The bombs are made from
their compressed form (zstd RLE blocks), so a file that expands to GiB costs
milliseconds to make.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import lz4.frame
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message, Statistics

MAGIC = b"\x89MCAP0\r\n"
T0 = 1_700_000_000 * 10**9
RECORD = struct.Struct("<BQ")  # a record's opcode and length


def record(item) -> bytes:
    builder = RecordBuilder()
    item.write(builder)
    return builder.end()


def message(channel: int, n: int, data: bytes) -> bytes:
    return record(Message(channel_id=channel, log_time=T0 + n * 10**7, data=data, publish_time=T0 + n * 10**7,
                          sequence=n))


def samples(channel: int, count: int, start: int = 0) -> bytes:
    """``count`` joint samples, one every 10 ms, as a recorder writes them."""
    return b"".join(message(channel, n, json.dumps({"t": (T0 + n * 10**7) / 1e9, "seq": n, "v": 0.5}).encode())
                    for n in range(start, start + count))


def zstd_zeros(size: int) -> bytes:
    """A zstd frame of ``size`` zero bytes, its content size not said, in RLE blocks: 4 bytes per 128 KiB."""
    block = 128 * 1024
    out = bytearray(b"\x28\xb5\x2f\xfd" + bytes([0x00, 0x58]))  # magic; no content size; window 128 MiB... (0x58)
    left = size
    while left > 0:
        n = min(block, left)
        left -= n
        header = (n << 3) | (1 << 1) | (1 if left == 0 else 0)  # RLE block, last flag
        out += header.to_bytes(3, "little") + b"\x00"
    return bytes(out)


def lz4_zeros(size: int) -> bytes:
    compressor = lz4.frame.LZ4FrameCompressor()
    out = [compressor.begin()]
    piece = bytes(1 << 22)
    for _ in range(size // len(piece)):
        out.append(compressor.compress(piece))
    out.append(compressor.flush())
    return b"".join(out)


def compress(content: bytes, compression: str) -> bytes:
    if compression == "zstd":
        return zstandard.ZstdCompressor().compress(content)
    if compression == "lz4":
        return lz4.frame.compress(content)
    return content


@dataclass
class Part:
    """A chunk: its ``content`` (records), compressed as ``compression``; ``data`` replaces the
    compressed bytes, ``declared`` the size the chunk says it expands to, ``indexed`` the size
    its index says (both default to the truth)."""

    content: bytes = b""
    compression: str = "zstd"
    data: bytes | None = None
    declared: int | None = None
    indexed: int | None = None
    channels: Sequence[int] = (1,)
    crc: bool = True


@dataclass
class Topic:
    id: int
    topic: str
    encoding: str = "json"
    count: int = 1


@dataclass
class Recipe:
    topics: list[Topic] = field(default_factory=lambda: [Topic(1, "pepper/joints/HeadYaw", count=10)])
    parts: list[Part] = field(default_factory=lambda: [Part(samples(1, 10))])
    channels_in_summary: bool = True
    times: tuple[int, int] = (T0, T0 + 10**9)  # the statistics' first and last message times


def craft(path, recipe: Recipe) -> bytes:
    """Write ``recipe`` to ``path``; returns the file's bytes."""
    out = bytearray(MAGIC)
    out += record(Header(profile="", library="crafted"))
    channels = [Channel(id=t.id, topic=t.topic, message_encoding=t.encoding, metadata={}, schema_id=0)
                for t in recipe.topics]
    for channel in channels:
        out += record(channel)
    indexes = []
    for part in recipe.parts:
        data = part.data if part.data is not None else compress(part.content, part.compression)
        declared = part.declared if part.declared is not None else len(part.content)
        start = len(out)
        out += record(Chunk(compression=part.compression if part.compression != "none" else "", data=data,
                            message_start_time=T0, message_end_time=T0 + 10**9,
                            uncompressed_crc=zlib.crc32(part.content) if part.crc else 0,
                            uncompressed_size=declared))
        indexes.append(ChunkIndex(chunk_length=len(out) - start, chunk_start_offset=start,
                                  compression=part.compression if part.compression != "none" else "",
                                  compressed_size=len(data), message_end_time=T0 + 10**9, message_index_length=0,
                                  message_index_offsets={}, message_start_time=T0,
                                  uncompressed_size=part.indexed if part.indexed is not None else declared))
    out += record(DataEnd(data_section_crc=0))
    summary_start = len(out)
    if recipe.channels_in_summary:
        for channel in channels:
            out += record(channel)
    total = sum(t.count for t in recipe.topics)
    out += record(Statistics(attachment_count=0, channel_count=len(channels),
                             channel_message_counts={t.id: t.count for t in recipe.topics}, chunk_count=len(indexes),
                             message_count=total, message_end_time=recipe.times[1], message_start_time=recipe.times[0],
                             metadata_count=0, schema_count=0))
    for index in indexes:
        out += record(index)
    out += record(Footer(summary_start=summary_start, summary_offset_start=0, summary_crc=0))
    out += MAGIC
    with open(path, "wb") as f:
        f.write(out)
    return bytes(out)


def jsons(channel: int, payloads: Iterable[bytes], start: int = 0) -> bytes:
    return b"".join(message(channel, start + n, p) for n, p in enumerate(payloads))
