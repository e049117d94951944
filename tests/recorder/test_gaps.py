"""Replay never waits on a gap longer than ``max_gap_s``: an hour of silence is
shortened to the bound with one warning line; a frame stamped an hour ahead (as
the recorder before issue 13 wrote it) is replayed when it was recorded, its ``t``
moved with it; every message after either is replayed."""

from __future__ import annotations

import json
import time

import pytest
from mcap.writer import CompressionType, Writer

from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.adapters.recorder.writer import RecordingWriter
from sonibus.bus import SampleQueue, decode
from sonibus.bus.errors import ConfigError

from ..conftest import run_cli, wait_for

JOINTS = ("HeadYaw", "HeadPitch", "LElbowRoll")
HOUR_NS = 3600 * 10**9
FRAME_NS = 20_000_000  # 50 frames/s


def rows(gap_ns: int, spike: bool) -> list[tuple[str, int, dict]]:
    """(key, log_ns, message): 20 frames, an hour's gap (``gap_ns``) or a frame stamped an hour
    ahead (``spike``), 20 frames and an event."""
    start = time.time_ns() - 10**9
    found = []
    for seq in range(40):
        log_ns = start + seq * FRAME_NS + (gap_ns if seq >= 20 else 0)
        t = log_ns / 1e9 + (3600 if spike and seq == 20 else 0)
        found += [(f"pepper/joints/{joint}", log_ns, {"t": t, "seq": seq, "v": seq / 100}) for joint in JOINTS]
    end = start + 40 * FRAME_NS + gap_ns
    found.append(("pepper/events/behavior", end, {"t": end / 1e9, "kind": "behavior", "state": "stopped", "name": "x"}))
    return found


def quiet_hour(path):
    """A recording with an hour of silence in it, as the recorder writes one."""
    with RecordingWriter(str(path)) as out:
        for key, log_ns, message in rows(HOUR_NS, spike=False):
            out.write(key, log_ns, message)


def stamped_ahead(path):
    """A recording with a frame stamped an hour ahead, as the recorder before issue 13
    wrote it: its ``t`` is its publish time."""
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start()
        channels = {}
        for key, log_ns, message in rows(0, spike=True):
            if key not in channels:
                channels[key] = writer.register_channel(key, "json", 0)
            writer.add_message(channels[key], log_ns, json.dumps(message).encode(), int(message["t"] * 1e9))
        writer.finish()


RECORDINGS = {"a quiet hour": quiet_hour, "a frame stamped an hour ahead": stamped_ahead}


def ordered_part_of_40(seqs: list[int], skipped: int) -> bool:
    """Frames 0..39 in order, less the ``skipped`` ones the replay was too late for on a busy machine."""
    return seqs == sorted(set(seqs)) and set(seqs) <= set(range(40)) and len(seqs) == 40 - skipped


@pytest.mark.parametrize("case", sorted(RECORDINGS))
def test_replay_shortens_a_long_gap_and_replays_all_after_it(net, tmp_path, case):
    path = tmp_path / "gap.mcap"
    RECORDINGS[case](path)
    watch = net.bus("watch")
    seen = SampleQueue(1 << 16)
    for pattern in ("pepper/frame", "pepper/events/*"):
        watch.subscribe(pattern, queue=seen)
    began = time.monotonic()
    replay = net.start(Replay(ReplayConfig(path=str(path), max_gap_s=0.5), name="replay"))
    wait_for(replay.finished.is_set, timeout=15, what="the replay to reach the end")
    assert time.monotonic() - began < 10  # not an hour: the gap took 0.5 s
    skipped = replay.stats["late"] // len(JOINTS)  # whole frames, by a busy machine: a few at most, never all after
    assert replay.stats["gaps"] >= (case == "a quiet hour") and skipped <= 2  # the gap (that is what is tested)
    got = []
    wait_for(lambda: got.extend(item[:2] for item in iter(lambda: seen.get(timeout=0), None))
             or len(got) >= 41 - skipped, what="every frame and the event")
    frames = [decode(payload) for key, payload in got if key == "pepper/frame"]
    assert ordered_part_of_40([f["seq"] for f in frames], skipped)
    assert all(f["names"] == list(JOINTS) for f in frames)
    assert all(abs(f["t"] - time.time()) < 30 for f in frames)  # on the replay's clock, the gap gone
    assert [decode(payload)["state"] for key, payload in got if key == "pepper/events/behavior"] == ["stopped"]


def test_a_looped_replay_does_not_wait_the_gap_between_passes(net, tmp_path):
    path = tmp_path / "gap.mcap"
    quiet_hour(path)
    replay = net.start(Replay(ReplayConfig(path=str(path), max_gap_s=0.5, loop=True), name="replay"))
    wait_for(lambda: replay.loops >= 3, timeout=20, what="three passes")


def test_replay_cli_warns_once_and_ends(net, tmp_path):
    path = tmp_path / "gap.mcap"
    quiet_hour(path)
    result = run_cli("replay", str(path), *net.cli_args(), timeout=30)  # the default bound: 5 s
    assert result.returncode == 0, result.stderr
    # (a replay nobody listens to says so too: that warning is not the gap's)
    warnings = [line for line in result.stderr.splitlines() if "WARNING" in line and "nobody on the bus" not in line]
    assert len(warnings) == 1 and "a gap of 3600.0 s before 3600.4 s into gap.mcap (pepper/joints/" in warnings[0] \
        and "replayed as 5 s (max_gap_s, --max-gap)" in warnings[0], result.stderr
    assert "1 gaps shortened" in result.stdout


def test_the_bound_is_checked():
    with pytest.raises(ConfigError, match="key 'max_gap_s'"):
        ReplayConfig(path="x.mcap", max_gap_s=0)


def test_publishers_whose_clocks_disagree_make_no_gaps(net, tmp_path):
    """Two publishers 6 s apart interleaved on one robot (a script beside the robot, or
    garbage with plausible times): their frames are replayed when they were recorded,
    not back and forth between two clocks (the fuzz suite's finding)."""
    path = tmp_path / "clocks.mcap"
    start = time.time_ns() - 10**9
    with RecordingWriter(str(path)) as out:
        for seq in range(40):
            log_ns = start + seq * FRAME_NS
            t = log_ns / 1e9 + (6.0 if seq % 2 else -6.0) * (seq % 3 == 0)
            for joint in JOINTS:
                out.write(f"pepper/joints/{joint}", log_ns, {"t": t, "seq": seq, "v": seq / 100})
    watch = net.bus("watch")
    seen = SampleQueue(1 << 16)
    watch.subscribe("pepper/frame", queue=seen)
    replay = net.start(Replay(ReplayConfig(path=str(path), max_gap_s=0.5), name="replay"))
    wait_for(replay.finished.is_set, timeout=15, what="the replay to reach the end")
    skipped = replay.stats["late"] // len(JOINTS)
    assert replay.stats["gaps"] == 0 and skipped <= 2
    frames = []
    wait_for(lambda: frames.extend(decode(item[1]) for item in iter(lambda: seen.get(timeout=0), None))
             or len(frames) >= 40 - skipped, what="every frame")
    assert ordered_part_of_40([f["seq"] for f in frames], skipped)
    assert all(abs(f["t"] - time.time()) < 10 for f in frames)  # each t moved with its frame
