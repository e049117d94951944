"""Hostile payloads on a live bus: every sink refuses them at the gate, counts them,
and goes on — nothing stalls, nothing is dropped, nothing reaches a file.
(Issue 13, items 4 and 5; the per-section rules are in test_messages.py.)"""

from __future__ import annotations

import time

import msgpack
import pytest
import zenoh

from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.recorder.reading import Recording
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.bus import ConfigError, config, keys
from sonibus.bus.messages import Limits

from .conftest import wait_for
from .osc.pd import Datagrams


def heard(receiver: Datagrams, address: bytes) -> int:
    return sum(1 for d in receiver.data() if d.startswith(address))


def test_huge_frames_and_future_times_are_refused_and_the_stream_goes_on(net, tmp_path):
    receiver = Datagrams()
    try:
        net.sim("pepper", rate_hz=50)
        sink = net.start(OscSink(OscSinkConfig(targets=(receiver.target,)), name="sound"))
        recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "show.mcap")), name="logger"))
        # blocking, so the router drops none of these big frames on a busy machine: each must be refused
        script = net.bus("script").session.declare_publisher(keys.frame("pepper"),
                                                             congestion_control=zenoh.CongestionControl.BLOCK)
        wait_for(lambda: heard(receiver, b"/pepper/joints/HeadYaw") >= 5, what="the simulator's joints")
        wait_for(lambda: recorder.stats.get("written", 0) > 0, what="the recorder writing")

        made_up = [f"Made{i}" for i in range(50_000)]
        huge = msgpack.packb({"t": time.time(), "seq": 1, "names": made_up, "v": [0.5] * len(made_up)})
        future = msgpack.packb({"t": time.time() + 3600, "seq": 2, "names": ["HeadYaw"], "v": [0.1]})
        for _ in range(20):
            script.put(huge)
            script.put(future)

        wait_for(lambda: sink.stats["bad"] >= 40 and recorder.stats["bad"] >= 40, timeout=30,
                 what="40 refusals in each",
                 explain=lambda: f"sink {sink.stats}, recorder {recorder.stats}")
        before = heard(receiver, b"/pepper/joints/HeadYaw")
        wait_for(lambda: heard(receiver, b"/pepper/joints/HeadYaw") >= before + 10, what="joints flowing on")
        assert sink.stats["bad"] == 40 and recorder.stats["bad"] == 40
        assert sink.dropped == 0 and recorder.status()["dropped"] == 0
        assert not any(d.startswith(b"/pepper/joints/Made") for d in receiver.data())
        assert sink.state == recorder.state == "running"
    finally:
        receiver.close()
    recorder.stop()
    with Recording(str(tmp_path / "show.mcap")) as recording:
        assert not [k for k in recording.counts if "Made" in k]
        assert all(m.data["t"] < time.time() for m in recording.messages() if "t" in m.data)


def test_garbage_from_made_up_robots_is_refused_before_anyone_asks_about_them(net):
    """A features node asks a robot for its info only once the robot's data passed the gate."""
    features = net.start(Features(FeaturesConfig(), name="features"))
    script = net.bus("script")
    publishers = [script.session.declare_publisher(keys.frame(f"made{i}")) for i in range(200)]
    wait_for(lambda: publishers[-1].matching_status.matching, what="the features node's frame subscription")
    for publisher in publishers:
        publisher.put(b"\xc1 not msgpack")
    wait_for(lambda: features.stats["bad"] >= 200, what="200 refusals", explain=lambda: str(features.stats))
    assert features.stats["bad"] == 200 and features.stats["waiting_info"] == 0
    for publisher in publishers:
        publisher.undeclare()


def test_the_clock_skew_tolerance_is_a_bus_setting(net, tmp_path):
    """[bus] max_future_s: a robot whose clock runs 30 s ahead is refused by default, heard with 60."""
    ahead = msgpack.packb({"t": time.time() + 30, "seq": 1, "names": ["HeadYaw"], "v": [0.25]})
    tolerant = net.bus("tolerant")
    tolerant.limits = Limits(max_future_s=60)
    strict = OscSink(OscSinkConfig(targets=("127.0.0.1:9",), max_age_ms=0), name="strict")
    lenient = OscSink(OscSinkConfig(targets=("127.0.0.1:9",), max_age_ms=0), name="lenient")
    net.start(strict)
    net.start(lenient, tolerant)
    script = net.bus("script").session.declare_publisher(keys.frame("pepper"))
    wait_for(lambda: script.matching_status.matching, what="the sinks' subscriptions")
    wait_for(lambda: script.put(ahead) or (strict.stats["received"] and lenient.stats["received"]), what="both")
    assert strict.stats["bad"] == strict.stats["received"] and lenient.stats["bad"] == 0
    with pytest.raises(ConfigError, match=r"key 'max_future_s': 0 must be more than 0 s"):
        config.parse("[bus]\nmax_future_s = 0\n[nodes.a]\nadapter = \"sim\"\n")
    assert config.parse("[bus]\nmax_future_s = 60\n[nodes.a]\nadapter = \"sim\"\n").bus.max_future_s == 60
