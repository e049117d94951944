"""Every file the recorder leaves, cut at any moment (a killed recorder, a full
disk, an unfinished copy), is either read whole or refused in one line that
says to run ``sonibus recover``; the recovered file then passes ``info``,
``export`` and the reading replay does. A file whose last chunk is torn is
never called fine."""

from __future__ import annotations

import io
import json
import struct

import pytest
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer

from sonibus.adapters.recorder import Recording, RecordingError, recover
from sonibus.adapters.recorder.replay import _moments
from sonibus.bus.cli import Environment, main

from ..conftest import Network
from .conftest import record_sim

CUTS = 120  # cuts spread over the whole file (besides the dense ones at its start and its last chunks)


@pytest.fixture(scope="module")
def chunky(tmp_path_factory):
    """A real recording of the simulator in several chunks (one every 0.12 s)."""
    path = tmp_path_factory.mktemp("chunky") / "show.mcap"
    network = Network()
    try:
        record_sim(network, path, frames=40, flush_s=0.12)  # (about 6 chunks: 4 at least on a busy machine)
    finally:
        network.close()
    return path


def cli(*argv):
    """``sonibus ARGV`` in this process: its exit status and stderr."""
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    return main(list(argv), env), env.stderr.getvalue()


def passes_every_reader(path, tmp_path):
    """``info``, ``export`` and what replay reads (its keys, the robots' info, every message, grouped as it
    sends them) all work on ``path``; returns its messages as recorded (a frame whole: one MCAP message)."""
    for argv in (["info", str(path)], ["export", str(path), "--csv", str(tmp_path / "csv")]):
        status, err = cli(*argv)
        assert status == 0 and err == "", (argv, err)
    with Recording(str(path)) as recording:
        assert recording.keys and recording.matching(["pepper/**"])
        recording.infos()
        samples = sum(1 for _ in recording.messages())
        assert sum(len(moment) for _, moment in _moments(recording.messages())) == samples
        found = [(m.key, m.log_ns, m.data) for m in recording.messages(frames=True)]
        assert sum(len(moment) for _, moment in _moments(recording.messages(frames=True))) == len(found)
    return found


def chunk_ends(path):
    """(end offset, messages) of each chunk of ``path``, in file order."""
    ends = []
    with open(path, "rb") as f:
        indexes = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda i: i.chunk_start_offset)
        for index in indexes:
            f.seek(index.chunk_start_offset)
            chunk = next(StreamReader(io.BytesIO(f.read(index.chunk_length)), skip_magic=True,
                                      emit_chunks=True).records)
            assert isinstance(chunk, Chunk)
            ends.append((index.chunk_start_offset + index.chunk_length,
                         sum(isinstance(r, McapMessage) for r in breakup_chunk(chunk))))
    return ends


def refused_with_the_recover_hint(path):
    for argv in (["info", str(path)], ["export", str(path), "--csv", str(path) + ".csv"]):
        status, err = cli(*argv)
        assert status == 1, (argv, err)
        assert err.startswith("sonibus: error: ") and err.count("\n") == 1, err
        assert f"sonibus recover {path}" in err, err
    with pytest.raises(RecordingError, match="sonibus recover"):
        Recording(str(path))


def test_a_recording_cut_anywhere_is_refused_with_the_recover_hint_and_recovers(chunky, tmp_path):
    data = chunky.read_bytes()
    whole = passes_every_reader(chunky, tmp_path)
    ends = chunk_ends(chunky)
    assert len(ends) >= 4, ends
    last_start = ends[-2][0]
    step = max(300, len(data) // CUTS)  # (a fixed 300 bytes grew to 111 s as the recordings grew)
    cuts = sorted({*range(1, len(data), step), *range(1, 40), *range(last_start, last_start + 40),
                   *range(ends[-1][0] - 20, ends[-1][0] + 20), len(data) - 1})
    recovered_counts = []
    for cut in cuts:
        path = tmp_path / f"cut-{cut}.mcap"
        path.write_bytes(data[:cut])
        refused_with_the_recover_hint(path)
        complete = sum(n for end, n in ends if end <= cut)
        out = tmp_path / f"cut-{cut}.recovered.mcap"
        if complete == 0:
            with pytest.raises(RecordingError, match="nothing to recover"):
                recover(str(path), str(out))
            assert not out.exists()
            continue
        assert recover(str(path), str(out)) == (complete, ""), cut
        found = passes_every_reader(out, tmp_path)
        assert found == whole[:complete], cut  # what was cut off is lost, the rest kept as it was
        recovered_counts.append(complete)
    assert recovered_counts[-1] == len(whole), "a cut after the last chunk keeps everything"


def test_a_torn_last_chunk_is_not_called_fine(tmp_path):
    """The file the recorder of issue 13 left after a frame with t = 1e12: a message
    record torn by ``struct.error`` inside the last chunk, then a summary that looks fine."""
    path = tmp_path / "torn.mcap"
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start()
        channel = writer.register_channel("pepper/joints/HeadYaw", "json", 0)
        for seq in range(5):
            writer.add_message(channel, 10**18 + seq, json.dumps({"t": 1e9, "seq": seq, "v": 0.1}).encode(), 10**18)
        writer.flush()  # the first chunk, whole
        for seq in range(5, 8):
            writer.add_message(channel, 10**18 + seq, json.dumps({"t": 1e9, "seq": seq, "v": 0.1}).encode(), 10**18)
        with pytest.raises(struct.error):  # what the writer of issue 13 met
            writer.add_message(channel, 10**18 + 8, b'{"t":1e12}', publish_time=10**21)
        for seq in range(9, 12):
            writer.add_message(channel, 10**18 + seq, json.dumps({"t": 1e9, "seq": seq, "v": 0.1}).encode(), 10**18)
        writer.finish()
    refused_with_the_recover_hint(path)
    _, err = cli("info", str(path))
    assert "is damaged" in err and "torn record" in err, err
    out = tmp_path / "torn.recovered.mcap"
    kept, _ = recover(str(path), str(out))
    found = passes_every_reader(out, tmp_path)
    assert [data["seq"] for _, _, data in found] == list(range(kept)) and kept >= 8  # up to the torn record
