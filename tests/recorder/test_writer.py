"""The writer checks each message whole before the file sees it: what it cannot
write is refused alone (``BadRecord``), the file stays readable, and a publish
time no clock could have given falls back to the log time."""

from __future__ import annotations

import contextlib
import math
import time

import pytest
from mcap.reader import make_reader

from sonibus.adapters.recorder import Recording
from sonibus.adapters.recorder.writer import MAX_CLOCK_OFFSET_S, BadRecord, RecordingWriter, WriteError

NOW_NS = time.time_ns()

UNWRITABLE = {  # message → what the error says
    "bytes": ({"t": NOW_NS / 1e9, "kind": "behavior", "name": b"x"}, "not strict JSON"),
    "NaN": ({"t": NOW_NS / 1e9, "seq": 1, "v": math.nan}, "not strict JSON"),
    "infinity": ({"t": NOW_NS / 1e9, "seq": 1, "v": -math.inf}, "not strict JSON"),
    "a set": ({"t": NOW_NS / 1e9, "kind": "x", "tags": {1, 2}}, "not strict JSON"),
    "a list": ([1, 2, 3], "not a map"),
}


def good(seq: int) -> dict:
    return {"t": NOW_NS / 1e9 + seq / 100, "seq": seq, "v": 0.5}


def messages_of(path):
    with open(path, "rb") as f:  # the mcap library's own reader: every record must decode
        return [(c.topic, m.log_time, m.publish_time, m.data) for _, c, m in make_reader(f).iter_messages()]


@pytest.mark.parametrize("what", sorted(UNWRITABLE))
def test_a_message_it_cannot_write_is_refused_alone_and_the_file_stays_whole(tmp_path, what):
    message, why = UNWRITABLE[what]
    path = tmp_path / "r.mcap"
    with RecordingWriter(str(path), flush_s=1e9) as out:
        out.write("pepper/joints/HeadYaw", NOW_NS, good(0))
        with pytest.raises(BadRecord, match=why) as refused:
            out.write("pepper/events/behavior", NOW_NS + 10**7, message)
        assert "\n" not in str(refused.value)
        out.write("pepper/joints/HeadYaw", NOW_NS + 2 * 10**7, good(1))
        assert out.messages == 2
    found = messages_of(path)
    assert [(topic, log) for topic, log, _, _ in found] == [("pepper/joints/HeadYaw", NOW_NS),
                                                           ("pepper/joints/HeadYaw", NOW_NS + 2 * 10**7)]
    with Recording(str(path)) as recording:
        assert [m.data["seq"] for m in recording.messages()] == [0, 1]


@pytest.mark.parametrize("log_ns", [-1, 1 << 64, 1.7e18])
def test_a_log_time_mcap_cannot_hold_is_refused(tmp_path, log_ns):
    with RecordingWriter(str(tmp_path / "r.mcap")) as out:
        with pytest.raises(BadRecord, match="log time"):
            out.write("pepper/joints/HeadYaw", log_ns, good(0))
        out.write("pepper/joints/HeadYaw", NOW_NS, good(1))
    assert len(messages_of(tmp_path / "r.mcap")) == 1


@pytest.mark.parametrize("t", [1e12, 1e30, -5.0, NOW_NS / 1e9 + 3600, NOW_NS / 1e9 - 3600, 10**400, math.inf, "soon",
                               True],
                         ids=["1e12", "1e30", "-5", "an hour ahead", "an hour ago", "10**400", "inf", "soon", "True"])
def test_a_publish_time_no_clock_gave_falls_back_to_the_log_time(tmp_path, t):
    """The frame of issue 13 (t = 1e12 overflowed uint64 ns: struct.error, a torn last chunk)."""
    path = tmp_path / "r.mcap"
    message = {"t": t, "seq": 1, "v": 0.1}
    with RecordingWriter(str(path)) as out:
        if isinstance(t, float) and math.isinf(t):
            with pytest.raises(BadRecord):  # not JSON at all
                out.write("pepper/joints/HeadYaw", NOW_NS, message)
            return
        out.write("pepper/joints/HeadYaw", NOW_NS, message)
    [(_, log_ns, publish_ns, _)] = messages_of(path)
    assert log_ns == publish_ns == NOW_NS
    with Recording(str(path)) as recording:  # the message itself is kept as it came; a reader checks it like the gate
        read = [m.data["t"] for m in recording.messages()]
        refused = t in (-5.0, "soon", True)  # (not a time)
        assert (read, recording.skipped["messages"]) == (([], 1) if refused else ([t], 0)), recording.problems()


def test_a_publish_time_near_the_log_time_is_kept(tmp_path):
    for i, offset_s in enumerate((-MAX_CLOCK_OFFSET_S + 1, -0.5, 0.0, 0.004, MAX_CLOCK_OFFSET_S - 1)):
        path = tmp_path / f"r{i}.mcap"
        with RecordingWriter(str(path)) as out:
            out.write("pepper/joints/HeadYaw", NOW_NS, {"t": NOW_NS / 1e9 + offset_s, "seq": 0, "v": 0.0})
        [(_, _, publish_ns, _)] = messages_of(path)
        assert abs(publish_ns - (NOW_NS + offset_s * 1e9)) < 1e3, offset_s


def test_a_closed_writer_says_so(tmp_path):
    out = RecordingWriter(str(tmp_path / "r.mcap"))
    out.close()
    out.close()  # twice is fine
    with pytest.raises(WriteError, match="it is closed"):
        out.write("pepper/joints/HeadYaw", NOW_NS, good(0))


def test_a_frame_written_in_one_go_is_the_same_file_as_message_by_message_and_a_bad_one_is_refused_alone(tmp_path):
    """``write_all`` (a frame's joints and views in one call, issue 35) writes what ``write``
    would have, message for message (topics, times, sequences, bytes), and skips only a
    message it cannot write, returning it with why."""
    frames = [[(f"pepper/joints/J{j}", {**good(seq), "v": j / 10}) for j in range(17)] +
              [("pepper/frame", {"t": NOW_NS / 1e9 + seq / 100, "seq": seq, "names": ["J0"], "v": [0.0]})]
              for seq in range(5)]
    frames[2][3] = ("pepper/joints/J3", UNWRITABLE["NaN"][0])
    one, many = tmp_path / "one.mcap", tmp_path / "many.mcap"
    with RecordingWriter(str(one), flush_s=1e9) as out:
        for seq, frame in enumerate(frames):
            for key, message in frame:
                with contextlib.suppress(BadRecord):
                    out.write(key, NOW_NS + seq, message)
    refused = []
    with RecordingWriter(str(many), flush_s=1e9) as out:
        for seq, frame in enumerate(frames):
            refused += out.write_all(frame, NOW_NS + seq)
        assert out.messages == 5 * 18 - 1
    assert [(key, "not strict JSON" in str(exc)) for key, exc in refused] == [("pepper/joints/J3", True)]
    first, second = records(one), records(many)
    assert first == second and len(first) == 5 * 18 - 1


def records(path):
    with open(path, "rb") as f:
        return [(c.topic, m.sequence, m.log_time, m.publish_time, m.data) for _, c, m in make_reader(f).iter_messages()]
