"""A file's chunk indexes kept on disk while it is written, not in memory.

mcap's ``Writer`` keeps one ``ChunkIndex`` per chunk in a list until ``finish`` writes
them into the summary. The recorder closes a chunk every ``flush_s`` (a second), and
each index holds a map of every channel in the chunk: about 4 KB with a Pepper's 50
keys, 15 MB an hour, for as long as the file is written — a recorder without rotation
grew for days. ``spill`` gives the writer a ``ChunkIndexes`` instead: each index is
made into its record at once and written to an unnamed temporary file beside the
recording, and ``finish`` gets the records back, in order, byte for byte.

>>> import io, os, tempfile
>>> from mcap.writer import Writer
>>> out = io.BytesIO()
>>> writer = Writer(out)
>>> indexes = spill(writer, tempfile.gettempdir())
>>> writer.start()
>>> channel = writer.register_channel("pepper/joints/HeadYaw", "json", 0)
>>> for second in range(3):
...     writer.add_message(channel, log_time=second, data=b"{}", publish_time=second)
...     writer.flush()
>>> writer.finish()
>>> indexes.close()
>>> from mcap.reader import make_reader
>>> len(make_reader(io.BytesIO(out.getvalue())).get_summary().chunk_indexes)
3
"""

from __future__ import annotations

import struct
import tempfile
from collections.abc import Iterator
from typing import Any

from mcap.data_stream import RecordBuilder
from mcap.records import ChunkIndex

_HEAD = struct.Struct("<BQ")  # a record's opcode and content length (MCAP's framing)
_ATTRIBUTE = "_Writer__chunk_indices"  # mcap's Writer's list (checked by tests/recorder/test_index.py)


class ChunkIndexes:
    """Stands in for the list of a ``Writer``'s chunk indexes: ``append`` writes the
    record to a temporary file in ``folder`` (gone when closed, or if the process dies);
    iterating gives back each as an object whose ``write(builder)`` copies the record."""

    def __init__(self, folder: str) -> None:
        self._file = tempfile.TemporaryFile(dir=folder, prefix=".sonibus-index-")  # noqa: SIM115 (the writer's life)
        self._count = 0

    def append(self, index: ChunkIndex) -> None:
        builder = RecordBuilder()
        index.write(builder)
        self._file.write(builder.end())
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[_Record]:
        self._file.flush()
        self._file.seek(0)
        for _ in range(self._count):
            head = self._file.read(_HEAD.size)
            _, length = _HEAD.unpack(head)
            yield _Record(head + self._file.read(length))
        self._file.seek(0, 2)  # (appending again after a summary was written: at the end)

    def close(self) -> None:
        self._file.close()


class _Record:
    """One chunk index, as its record's bytes."""

    __slots__ = ("raw",)

    def __init__(self, raw: bytes) -> None:
        self.raw = raw

    def write(self, builder: RecordBuilder) -> None:
        builder.write(self.raw)


def spill(writer: Any, folder: str) -> ChunkIndexes | None:
    """Keep ``writer``'s chunk indexes in a temporary file in ``folder`` (close it once the
    writer is finished); None, and the list left as it is, if this version of mcap keeps
    them elsewhere (tests/recorder/test_index.py fails then)."""
    if not isinstance(getattr(writer, _ATTRIBUTE, None), list):
        return None
    indexes = ChunkIndexes(folder)
    setattr(writer, _ATTRIBUTE, indexes)
    return indexes
