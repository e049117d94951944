"""A replay keeps its time while its recording is being read (issue 29, item 12): on a
busy machine a ×2 replay skipped a third of its samples as late, and the first ones
of every run. Reading a recording is bursty — the MCAP reader decodes a whole chunk
(a second of data) at once, milliseconds, hundreds of them on a machine whose CPU is
taken — and the burst ran on the player's thread, so everything due meanwhile was
late; the replay's start was also set before its first read. The burst is played
here by a recording whose reading stalls where the real one would. Its progress line
follows its clock (item 13)."""

from __future__ import annotations

import time

import pytest

from sonibus.adapters.recorder import reading
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.adapters.recorder.writer import RecordingWriter

from ..conftest import wait_for
from .test_gaps import rows

STALL_S = 2.0     # how long the reading stalls (a chunk decoded on a machine whose CPU is taken)
FRAMES_S = 50     # the recording's frames per second
JOINTS = 3        # (few: reading must keep ahead on a machine busy with other tests too)
LENGTH_S = 6


@pytest.fixture
def stalling(monkeypatch):
    """Make the replay's ``which`` reading of the recording (``prime``: its first, the
    offsets it starts from; ``play``: the messages it plays) stall ``STALL_S`` at message ``at``."""
    original = reading.Recording.messages

    def install(which: str, at: int) -> None:
        readings: list[int] = []

        def messages(self, keys=None, start_s=None, end_s=None, frames=False):
            if keys is not None and all(k.endswith("/info") for k in keys):  # (its info, read at start)
                yield from original(self, keys, start_s, end_s, frames)
                return
            readings.append(1)
            stalls = len(readings) == (1 if which == "prime" else 2)
            for i, message in enumerate(original(self, keys, start_s, end_s, frames)):
                if stalls and i == at:
                    time.sleep(STALL_S)
                yield message

        monkeypatch.setattr(reading.Recording, "messages", messages)
    return install


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A recording of a robot's joints at 50 frames/s for 6 s, as the recorder writes one."""
    path = tmp_path_factory.mktemp("late") / "six.mcap"
    start = time.time_ns() - 10 * 10**9
    with RecordingWriter(str(path)) as out:
        for seq in range(LENGTH_S * FRAMES_S):
            log_ns = start + seq * 10**9 // FRAMES_S
            for j in range(JOINTS):
                out.write(f"pepper/joints/J{j}", log_ns, {"t": log_ns / 1e9, "seq": seq, "v": j / 100})
    return path


@pytest.mark.parametrize(("which", "at_s"), [("prime", 0.0), ("play", 3.5)],
                         ids=["its first read", "a chunk 3.5 s in"])
def test_a_slow_read_of_the_recording_makes_nothing_late(net, recording, stalling, which, at_s):
    stalling(which, int(at_s * FRAMES_S * JOINTS))
    replay = net.start(Replay(ReplayConfig(path=str(recording)), name="take"))
    wait_for(replay.finished.is_set, timeout=30, what="the replay to finish")
    late_frames = replay.stats["late"] / JOINTS
    # before: every frame due in the stall (90 and 100 of them); a machine busy with other tests
    # may still make a few late, not a stall's worth
    assert late_frames < STALL_S * FRAMES_S / 2, replay.stats
    assert replay.stats["frames"] > 0


def test_the_progress_follows_the_replays_clock_through_a_gap(net, tmp_path):
    """Issue 29, item 13: the progress line showed where the last message sent was, so it
    stood still through a quiet part of a recording (and showed the end of the last pass
    with the next pass's number): it lagged. It follows the replay's clock now."""
    path = tmp_path / "quiet.mcap"
    with RecordingWriter(str(path)) as out:
        for key, log_ns, message in rows(2 * 10**9, spike=False):  # 0.4 s of frames, 2 s of silence, 0.4 s
            out.write(key, log_ns, message)
    replay = net.start(Replay(ReplayConfig(path=str(path)), name="take"))
    shown: list[float] = []
    wait_for(lambda: shown.append(replay.position_s) or 1.0 < shown[-1] < 2.0, timeout=10,
             what="a position inside the quiet part", explain=lambda: f"shown: {sorted(set(shown))}")
    wait_for(replay.finished.is_set, timeout=10, what="the replay to finish")
    assert replay.position_s == pytest.approx(replay.window_s)
    assert shown == sorted(shown), "it never goes back"
