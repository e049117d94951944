"""A replay sends on time while its recording is being read (issue 29, item 12): on a
busy machine a ×2 replay skipped a third of its samples as late, and the first ones
of every run. Reading a recording is bursty — the MCAP reader decodes a whole chunk
(a second of data) at once, milliseconds, hundreds of them on a machine whose CPU is
taken — and the burst ran on the player's thread, so everything due meanwhile was
late; the replay's start was also set before its first read. The burst is played
here by a recording whose reading stalls where the real one would."""

from __future__ import annotations

import time

import pytest

from sonibus.adapters.recorder import reading
from sonibus.adapters.recorder.replay import Replay, ReplayConfig

from ..conftest import wait_for

STALL_S = 1.0     # how long the reading stalls (a chunk decoded on a machine whose CPU is taken)
FRAMES_S = 50     # the recording's frames per second (the `recorded` fixture's)
JOINTS = 17


@pytest.fixture
def stalling(monkeypatch):
    """Make the replay's ``which`` reading of the recording (``prime``: its first, the
    offsets it starts from; ``play``: the messages it plays) stall ``STALL_S`` at message ``at``."""
    original = reading.Recording.messages

    def install(which: str, at: int) -> None:
        readings: list[int] = []

        def messages(self, keys=None, start_s=None, end_s=None):
            if keys is not None and all(k.endswith("/info") for k in keys):  # (its info, read at start)
                yield from original(self, keys, start_s, end_s)
                return
            readings.append(1)
            stalls = len(readings) == (1 if which == "prime" else 2)
            for i, message in enumerate(original(self, keys, start_s, end_s)):
                if stalls and i == at:
                    time.sleep(STALL_S)
                yield message

        monkeypatch.setattr(reading.Recording, "messages", messages)
    return install


@pytest.mark.parametrize(("which", "at"), [("prime", 0), ("play", JOINTS * FRAMES_S * 3 // 2)],
                         ids=["its first read", "a chunk 1.5 s in"])
def test_a_slow_read_of_the_recording_makes_nothing_late(net, recorded, stalling, which, at):
    path, _ = recorded
    stalling(which, at)
    replay = net.start(Replay(ReplayConfig(path=str(path)), name="take"))
    wait_for(replay.finished.is_set, timeout=30, what="the replay to finish")
    due_in_a_stall = int(STALL_S * FRAMES_S * JOINTS)
    # (a few samples may still be late on a machine whose CPU is taken: not a stall's worth)
    assert replay.stats["late"] < due_in_a_stall / 5, (replay.stats, due_in_a_stall)
    assert replay.stats["sent"] > 0
