"""``RecordingWriter``: bus messages into an MCAP file, one channel per key.

Chunks are closed every ``flush_s`` seconds (and at ``chunk_bytes``), written
through and fsync'ed, so a recorder killed without warning leaves a file that
holds everything up to the last closed chunk; ``close()`` adds the summary and
index that make a file seekable.

>>> import os, tempfile
>>> path = os.path.join(tempfile.mkdtemp(), "doc.mcap")
>>> with RecordingWriter(path) as out:
...     out.write("pepper/joints/HeadYaw", 1_700_000_000_000_000_000, {"t": 1.7e9, "seq": 0, "v": 0.1})
>>> out.messages
1
"""

from __future__ import annotations

import os
import time
from importlib.metadata import version
from typing import Any, BinaryIO

from mcap.writer import CompressionType, Writer

from sonibus import schemas

from .channels import MESSAGE_ENCODING, PROFILE, SCHEMA_ENCODING, SCHEMA_PREFIX, schema_for, to_json

METADATA_RECORDING = "sonibus.recording"
METADATA_STATS = "sonibus.stats"


class RecordingWriter:
    """Writes messages as they come; ``close()`` (or leaving ``with``) finishes the file."""

    def __init__(self, path: str, metadata: dict[str, str] | None = None, flush_s: float = 1.0,
                 chunk_bytes: int = 1 << 20) -> None:
        self.path = path
        self.flush_s = flush_s
        self._file: BinaryIO = open(path, "wb")  # noqa: SIM115 — closed by close()
        self._writer = Writer(self._file, chunk_size=chunk_bytes, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library=f"sonibus {version('sonibus')}")
        if metadata is not None:
            self._writer.add_metadata(METADATA_RECORDING, metadata)
        self._schemas: dict[str | None, int] = {None: 0}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self._last_flush = time.monotonic()
        self.messages = 0
        self.closed = False

    def write(self, key: str, log_ns: int, message: dict[str, Any]) -> None:
        """One message received at ``log_ns`` (ns since the epoch); its ``t``, if any, is the publish time."""
        channel = self._channels.get(key)
        if channel is None:
            channel = self._channels[key] = self._channel(key)
        t = message.get("t")
        publish_ns = int(t * 1e9) if isinstance(t, int | float) and not isinstance(t, bool) and t >= 0 else log_ns
        sequence = self._sequence[channel] = self._sequence.get(channel, -1) + 1
        self._writer.add_message(channel, log_time=log_ns, data=to_json(message), publish_time=publish_ns,
                                 sequence=sequence)
        self.messages += 1
        if time.monotonic() - self._last_flush >= self.flush_s:
            self.flush()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, data)

    def flush(self) -> None:
        """Close the chunk in progress and put it on disk."""
        self._writer.flush()
        os.fsync(self._file.fileno())
        self._last_flush = time.monotonic()

    def close(self, stats: dict[str, Any] | None = None) -> None:
        """Write ``stats`` as metadata, the summary and the index; safe to call twice."""
        if self.closed:
            return
        self.closed = True
        try:
            if stats:
                self._writer.add_metadata(METADATA_STATS, {k: str(v) for k, v in stats.items()})
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
        finally:
            self._file.close()

    @property
    def size(self) -> int:
        """Bytes on disk so far."""
        return self._file.tell() if not self.closed else os.path.getsize(self.path)

    def _channel(self, key: str) -> int:
        name = schema_for(key)
        schema_id = self._schemas.get(name)
        if schema_id is None:
            schema_id = self._schemas[name] = self._writer.register_schema(
                SCHEMA_PREFIX + name, SCHEMA_ENCODING, to_json(schemas.load(name)))
        return self._writer.register_channel(key, MESSAGE_ENCODING, schema_id)

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
