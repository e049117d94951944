"""Frames (``<robot>/frame``): the recorder takes them and writes the samples of
their joint keys; replay puts a recording's frames back whole beside the joint
keys, so sinks that listen on frames get every joint."""

from __future__ import annotations

import re
import signal
import struct
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from pythonosc.osc_packet import OscPacket

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.recorder import Recording
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.adapters.sim import SimRobot
from sonibus.bus import SampleQueue, config, decode, encode, runner
from sonibus.bus.framing import frame as frame_message
from sonibus.bus.framing import frame_samples

from ..conftest import SONIBUS, Network, wait_for
from ..osc.pd import Datagrams
from .conftest import record_sim, settle
from .test_record import read_back

JOINTS = 17


class ExtrasSim(SimRobot):
    """The simulator with a commanded position and a temperature per joint (as the NAOqi adapter sends)."""

    def publish_frame(self, t, seq, positions, names=None, extra=None):
        super().publish_frame(t, seq, positions, names,
                              {"cmd": [p + 0.25 for p in positions], "temp": [40.0 + seq % 7] * len(positions)})


@pytest.fixture(scope="module")
def with_extras(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[str, dict[str, Any]]]]:
    """A recording of ``ExtrasSim`` (60 frames) and what its joint keys carried meanwhile."""
    path = tmp_path_factory.mktemp("rec") / "extras.mcap"
    network = Network()
    try:
        _, reference = record_sim(network, path, frames=60, robot=ExtrasSim)
    finally:
        network.close()
    return path, reference


def by_seq(messages) -> dict[int, dict[str, tuple[int, dict]]]:
    """Joint samples of a file by frame: seq → joint key → (log time, sample); a frame (one MCAP message
    since issue 35) taken apart with ``frame_samples``."""
    frames: dict[int, dict[str, tuple[int, dict]]] = defaultdict(dict)
    for topic, log_ns, _, data, _ in messages:
        if "/joints/" in topic:
            frames[data["seq"]][topic] = (log_ns, data)
        elif topic.endswith("/frame"):
            for name, sample in frame_samples(data):
                frames[data["seq"]][f"{topic.partition('/')[0]}/joints/{name}"] = (log_ns, sample)
    return frames


def test_a_frame_is_written_whole_and_read_as_the_samples_of_its_joint_keys_with_extras(with_extras):
    path, reference = with_extras
    _, messages, metadata = read_back(path)
    whole = [data["seq"] for topic, _, _, data, _ in messages if topic == "pepper/frame"]
    assert whole == sorted(set(whole)) and not any("/joints/" in topic for topic, *_ in messages)  # one a frame
    frames = by_seq(messages)
    with Recording(str(path)) as recording:  # what readers give: each joint's sample on its key
        assert by_seq([(m.key, m.log_ns, m.publish_ns, m.data, None) for m in recording.messages()]) == frames
    assert len(frames) >= 60  # frames the robot skipped (a VM stall) are on no key: compared below
    for seq, joints in frames.items():
        assert len(joints) == JOINTS, f"frame {seq}: {len(joints)} joints"
        assert len({log_ns for log_ns, _ in joints.values()}) == 1, f"frame {seq}: not written from one frame"
        for key, (_, data) in joints.items():
            assert set(data) == {"t", "seq", "v", "cmd", "temp"}, (key, data)
            assert data["cmd"] == data["v"] + 0.25 and data["temp"] == 40.0 + seq % 7
    # What each joint key carried, as the file holds it (either may miss the robot's first frame).
    seen = defaultdict(list)
    for key, data in reference:
        seen[key].append(data)
    for key, data in seen.items():
        if "/joints/" in key:
            in_file = [frames[seq][key][1] for seq in sorted(frames)]
            both = min(len(in_file), len(data))
            assert in_file[-both:] == data[-both:] and abs(len(in_file) - len(data)) <= 2, key
    stats = metadata["sonibus.stats"]
    assert stats["bad"] == "0" and stats["dropped"] == "0" and int(stats["received"]) == int(stats["written"])


def test_per_joint_keys_records_a_publisher_of_joint_keys_only(net, tmp_path, spawn):
    keyed, framed = tmp_path / "keyed.mcap", tmp_path / "framed.mcap"
    recording = spawn(SONIBUS, "record", str(keyed), "--per-joint-keys", *net.cli_args(), "--status-every", "0.1",
                      collect=True, merge=True)
    bus = net.bus("script")  # a script of one's own: joint keys, no frames
    publishers = [bus.stream_publisher(f"script/joints/{j}") for j in "AB"]
    events, frames = (bus.session.declare_publisher(k) for k in ("script/events/done", "script/frame"))
    # Only the --per-joint-keys recorder subscribes to joint keys and (so far) to events: these match once
    # its subscriptions are here.
    wait_for(lambda: all(p.matching_status.matching for p in [*publishers, events]), timeout=20,
             what="the CLI recorder's subscriptions")
    default = net.start(Recorder(RecorderConfig(path=str(framed)), name="logger"))
    wait_for(lambda: frames.matching_status.matching, what="the default recorder's subscriptions")
    for seq in range(20):
        for i, publisher in enumerate(publishers):
            publisher.put(encode({"t": time.time(), "seq": seq, "v": seq + i / 10}))

    def done() -> bool:  # both recorders take events (the default one's event subscription may come last)
        bus.put("script/events/done", {"t": time.time(), "kind": "done"})
        return default.stats["written"] >= 1

    wait_for(done, what="the event in the default recorder")
    wait_for(lambda: any(int(m[1]) >= 41 for line in recording.lines if (m := re.search(r" (\d+) messages", line))),
             timeout=10, what="40 samples and the event in the keyed file",
             explain=lambda: "\n".join(recording.lines[-3:]))
    recording.popen.send_signal(signal.SIGINT)  # not stop(): the lines are being collected from its stdout
    assert recording.popen.wait(10) == 0
    default.stop()
    _, messages, _ = read_back(keyed)
    assert [(t, d["seq"], d["v"]) for t, _, _, d, _ in messages if "/joints/" in t] == [
        (f"script/joints/{j}", seq, seq + i / 10) for seq in range(20) for i, j in enumerate("AB")]
    _, messages, _ = read_back(framed)
    keys = [m for m in messages if m[0] != "script/log"]  # (the event's Foxglove log line is a view, not a key)
    assert {t for t, *_ in keys} == {"script/events/done"}, "without per_joint_keys it listens on frames only"
    assert default.stats["received"] == default.stats["written"] == len(keys)


def test_per_joint_keys_in_an_installation_file(tmp_path):
    (recorder,) = runner.build(config.parse(f'[nodes.logger]\nadapter = "recorder"\npath = "{tmp_path}/x.mcap"\n'
                                            'per_joint_keys = true\n'))
    assert recorder.config.per_joint_keys is True


def test_a_bad_frame_is_counted_and_the_recording_goes_on(net, tmp_path):
    path = tmp_path / "bad.mcap"
    recorder = net.start(Recorder(RecorderConfig(path=str(path), foxglove=False), name="logger"))
    frames = net.bus("script").stream_publisher("bot/frame")
    wait_for(lambda: frames.matching_status.matching, what="the recorder's frame subscription")
    good = frame_message(time.time(), 0, ["A", "B"], [0.1, 0.2], {"cmd": [0.3, 0.4]})
    bad = [b"\xc1 not msgpack", encode([1, 2]), encode({**good, "v": [0.1]}), encode({**good, "names": ["A", "x/y"]}),
           encode({**good, "names": ["A", "x$y"]}), encode({**good, "names": ["A", "**"]}),
           encode({**good, "cmd": [0.3]}), encode({**good, "t": "now"}), encode({k: v for k, v in good.items()
                                                                                 if k != "seq"})]
    frames.put(encode(good))
    for payload in bad:
        frames.put(payload)
    frames.put(encode({**good, "seq": 1}))
    wait_for(lambda: recorder.stats["written"] >= 4, what="both good frames",
             explain=lambda: str(recorder.stats))
    settle(lambda: dict(recorder.stats))
    assert recorder.stats == {"received": 4 + len(bad), "written": 4, "bad": len(bad)}
    assert recorder.state == "running"
    recorder.stop()
    _, messages, metadata = read_back(path)
    assert [(t, d) for t, _, _, d, _ in messages] == [("bot/frame", {**good, "seq": seq}) for seq in (0, 1)]
    with Recording(str(path)) as recording:
        assert [(m.key, m.data) for m in recording.messages()] == [
            ("bot/joints/A", {"t": good["t"], "seq": seq, "v": 0.1, "cmd": 0.3}) if j == "A" else
            ("bot/joints/B", {"t": good["t"], "seq": seq, "v": 0.2, "cmd": 0.4}) for seq in (0, 1) for j in "AB"]
    assert metadata["sonibus.stats"]["bad"] == str(len(bad))


def osc_messages(receiver: Datagrams, prefix: str) -> list[tuple[str, float]]:
    return [(timed.message.address, timed.message.params[0]) for dgram in receiver.data()
            for timed in OscPacket(dgram).messages if timed.message.address.startswith(prefix)]


def f32(value: float) -> float:
    return struct.unpack("f", struct.pack("f", value))[0]


def test_replay_into_a_default_osc_sink_delivers_every_joint_of_every_frame(net, recorded):
    path, _ = recorded
    receiver = Datagrams()
    try:
        # The sink's default subscription (frames); no stale check, so a busy machine cannot drop a frame.
        sink = net.start(OscSink(OscSinkConfig(targets=(receiver.target,), max_age_ms=0), name="sound"))
        replay = net.start(Replay(ReplayConfig(path=str(path), rename={"pepper": "take1"}), name="take"))
        wait_for(replay.finished.is_set, timeout=20, what="the end of the replay")
        with Recording(str(path)) as recording:
            expected = [(f"/take1/joints/{m.key.rpartition('/')[2]}", f32(m.data["v"]))
                        for m in recording.messages() if "/joints/" in m.key]
        recorded_frames = [expected[i:i + JOINTS] for i in range(0, len(expected), JOINTS)]
        # (a frame the replay is too late for on a busy machine is skipped whole, and counted)
        assert replay.stats["frames"] + replay.stats["late"] // JOINTS == len(recorded_frames)
        settle(lambda: len(receiver.items))
        got = osc_messages(receiver, "/take1/joints/")
        delivered = [got[i:i + JOINTS] for i in range(0, len(got), JOINTS)]
        left = iter(recorded_frames)
        # (a frame the sink skipped after a stall of a busy machine, never sent as a burst, is counted)
        assert len(delivered) + sink.stats["skipped"] == replay.stats["frames"] and all(
            frame in left for frame in delivered), "every frame published reaches the sink whole, in order"
    finally:
        receiver.close()


def test_replay_publishes_each_frame_whole_and_per_joint_with_the_same_values(net, with_extras):
    path, _ = with_extras
    bus = net.bus("watch")
    seen = SampleQueue(1 << 20)
    for pattern in ("take1/frame", "take1/joints/*"):
        bus.subscribe(pattern, queue=seen)
    replay = net.start(Replay(ReplayConfig(path=str(path), rename={"pepper": "take1"}, loop=True, speed=2.0),
                              name="take"))
    wait_for(lambda: replay.loops >= 2, timeout=20, what="two passes")
    replay.stop()
    settle(lambda: len(seen))
    frames, joints = {}, defaultdict(dict)
    while (item := seen.get(timeout=0)) is not None:
        key, message = item[0], decode(item[1])
        if key == "take1/frame":
            assert message["seq"] > max(frames, default=-1), "seq keeps counting up across passes"
            frames[message["seq"]] = message
        else:
            joints[message["seq"]][key.rpartition("/")[2]] = message
    with Recording(str(path)) as recording:
        per_pass = recording.counts["pepper/joints/HeadYaw"]
    # (frames more than 100 ms late, on a stalled machine, are skipped whole)
    assert len(frames) >= 2 * per_pass - 2 - replay.stats["late"] // JOINTS
    for seq, frame in frames.items():
        names, values = frame["names"], frame["v"]
        assert len(names) == JOINTS and set(frame) == {"t", "seq", "names", "v", "cmd", "temp"}
        assert abs(frame["t"] - time.time()) < 5, "t is moved to now"
        assert joints[seq] == {name: {"t": frame["t"], "seq": seq, "v": values[i], "cmd": frame["cmd"][i],
                                      "temp": frame["temp"][i]} for i, name in enumerate(names)}
    assert set(joints) == set(frames), "every joint sample has its frame"


def test_replay_gathers_a_frame_whose_joints_are_interleaved_with_another_robots():
    """Per-joint recordings (older files, ``per_joint_keys``) interleave robots' samples."""
    from sonibus.adapters.recorder.reading import Message
    from sonibus.adapters.recorder.replay import _moments

    def sample(key: str, log_ns: int, seq: int, t: float) -> Message:
        return Message(key, log_ns, int(t * 1e9), {"t": t, "seq": seq, "v": 0.1})

    recorded = [sample("pepper/joints/HeadYaw", 0, 5, 1.0), sample("nao/joints/HeadYaw", 100, 9, 1.001),
                sample("pepper/joints/HeadPitch", 200, 5, 1.0), Message("pepper/events/x", 250, 0, {"kind": "x"}),
                sample("nao/joints/HeadPitch", 300, 9, 1.001), sample("pepper/joints/HeadYaw", 10_000_000, 6, 1.01)]
    assert [(framed, [m.key for m in moment]) for framed, moment in _moments(recorded)] == [
        (True, ["pepper/joints/HeadYaw", "pepper/joints/HeadPitch"]),
        (True, ["nao/joints/HeadYaw", "nao/joints/HeadPitch"]),
        (False, ["pepper/events/x"]),
        (True, ["pepper/joints/HeadYaw"]),
    ]
