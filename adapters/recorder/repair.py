"""``recover``: what can be read of a damaged recording (a killed recorder's, a full disk's,
an unfinished copy's) copied into a new, complete one: every complete chunk, and of a
damaged chunk the records before the damage; each message checked as ``Recording`` checks it.

>>> import os, tempfile
>>> from sonibus.adapters.recorder.writer import RecordingWriter
>>> folder = tempfile.mkdtemp()
>>> with RecordingWriter(os.path.join(folder, "cut.mcap")) as out:
...     out.write("pepper/joints/HeadYaw", 10**8, {"t": 0.1, "seq": 0, "v": 0.5})
>>> whole = open(os.path.join(folder, "cut.mcap"), "rb").read()
>>> _ = open(os.path.join(folder, "cut.mcap"), "wb").write(whole[:-40])  # its end torn off
>>> recover(os.path.join(folder, "cut.mcap"), os.path.join(folder, "kept.mcap"))
(1, '')
>>> import shutil; shutil.rmtree(folder)
"""

from __future__ import annotations

import os

from mcap.records import Channel, Metadata
from mcap.records import Message as McapMessage

from .bounded import DAMAGE, MAX_CHANNELS, MAX_TOPIC, ChunkError, records
from .channels import AUDIO_ENCODING, MESSAGE_ENCODING, is_view
from .reading import MAGIC, Checks, RecordingError, data_key
from .writer import METADATA_RECORDING, BadRecord, RecordingWriter

__all__ = ["recover"]


def recover(path: str, out: str) -> tuple[int, str]:
    """Copy every message of the damaged recording ``path`` that can be read into a
    new, complete recording ``out``; returns how many, and what was skipped ("" if
    nothing was: a message the recorder would not write, a chunk that cannot be read)."""
    try:
        with open(path, "rb") as f:
            head = f.read(len(MAGIC))
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror}") from None
    if not MAGIC.startswith(head):
        raise RecordingError(f"{path} is not an MCAP file (it starts with {head[:8]!r})")
    channels: dict[int, Channel] = {}
    kept, checks = 0, Checks(path)
    bad: list[ChunkError] = []
    with open(path, "rb") as f, RecordingWriter(out) as writer:
        try:
            for record in records(f, bad):
                if isinstance(record, Channel):
                    if len(channels) < MAX_CHANNELS and len(record.topic) <= MAX_TOPIC and \
                            record.message_encoding in (MESSAGE_ENCODING, AUDIO_ENCODING) and \
                            (is_view(record.topic) or data_key(record.topic)):
                        channels[record.id] = record
                elif isinstance(record, McapMessage) and record.channel_id in channels:
                    found = checks.message(channels[record.channel_id], record)
                    if found is None:
                        continue
                    try:
                        writer.write(found.key, found.log_ns, found.data)
                    except BadRecord as exc:  # (from an older recorder): the rest is kept
                        checks.skip("messages", f"{found.key}: {exc}")
                        continue
                    kept += 1
                elif isinstance(record, Metadata) and record.name == METADATA_RECORDING:
                    writer.add_metadata(record.name, dict(record.metadata))
        except DAMAGE:
            pass  # the damaged end: everything before it is kept
    for exc in bad:
        checks.skip("chunks", str(exc))
    if kept == 0:
        os.unlink(out)
        more = f": {checks.problems().partition(': ')[2]}" if checks.problems() else ""
        raise RecordingError(f"{path} holds no complete chunk: nothing to recover{more}")
    return kept, checks.problems()
