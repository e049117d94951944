"""A file's chunk indexes wait on disk, not in memory (adapters/recorder/index.py): a
recorder without rotation grew 15 MB an hour with a Pepper's keys (issue 25, flat memory)."""

from __future__ import annotations

import io
import os
import tracemalloc

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from sonibus.adapters.recorder import index
from sonibus.adapters.recorder.reading import Recording
from sonibus.adapters.recorder.writer import RecordingWriter

KEYS = [f"pepper/joints/J{i}" for i in range(17)] + [f"pepper/derived/velocity/J{i}" for i in range(26)]
T0 = 1_700_000_000


def _second(out: RecordingWriter, second: int) -> None:
    """One second of a show: a message of every key, then the chunk closed (as every flush_s)."""
    for key in KEYS:
        out.write(key, (T0 + second) * 10**9, {"t": T0 + second, "seq": second, "v": 0.1})
    out.flush()


def test_a_long_file_holds_no_more_memory_at_its_350th_chunk_than_at_its_100th(tmp_path):
    tracemalloc.start()
    try:
        with RecordingWriter(str(tmp_path / "long.mcap")) as out:
            for second in range(100):
                _second(out, second)
            before = tracemalloc.get_traced_memory()[0]
            for second in range(100, 350):
                _second(out, second)
            grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    # kept in memory, 250 chunk indexes of 43 keys were 1 MB (4 KB each)
    assert grown < 200_000, f"{grown:,} bytes more after 250 chunks"
    with open(tmp_path / "long.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.chunk_count == len(summary.chunk_indexes) == 350
    recording = Recording(str(tmp_path / "long.mcap"))  # (as info, export and replay open it)
    assert recording.message_count == sum(1 for _ in recording.messages()) == 350 * len(KEYS)


def test_the_file_is_byte_for_byte_what_it_was_with_the_indexes_in_memory(tmp_path):
    files = []
    for spilled in (False, True):
        out = io.BytesIO()
        writer = Writer(out, compression=CompressionType.ZSTD)
        indexes = index.spill(writer, str(tmp_path)) if spilled else None
        writer.start(profile="sonibus", library="test")
        channels = [writer.register_channel(key, "json", 0) for key in KEYS[:5]]
        for second in range(50):
            for channel in channels:
                writer.add_message(channel, log_time=second, data=b'{"v": 0.1}', publish_time=second)
            writer.flush()
        writer.finish()
        if indexes is not None:
            assert len(indexes) == 50
            indexes.close()
        files.append(out.getvalue())
    assert files[0] == files[1]
    summary = make_reader(io.BytesIO(files[1])).get_summary()
    assert [i.message_start_time for i in summary.chunk_indexes] == list(range(50))


def test_mcap_keeps_its_chunk_indexes_where_the_recorder_looks_for_them(tmp_path):
    # (an mcap that moved them: the recorder would grow again, silently; this says so)
    assert index.spill(Writer(io.BytesIO()), str(tmp_path)) is not None


def test_the_temporary_file_is_never_seen_and_closed_with_the_recording(tmp_path):
    fds = len(os.listdir("/proc/self/fd"))
    out = RecordingWriter(str(tmp_path / "show.mcap"))
    _second(out, 0)
    assert os.listdir(tmp_path) == ["show.mcap"]  # (unnamed: nothing to clean up after a crash)
    out.close()
    assert len(os.listdir("/proc/self/fd")) == fds
    abandoned = RecordingWriter(str(tmp_path / "cut.mcap"))
    _second(abandoned, 0)
    abandoned.abandon()
    assert len(os.listdir("/proc/self/fd")) == fds
