"""The OSC sink takes joints from each robot's ``<robot>/frame`` (bus/streams.py):
patterns still select joints, nothing arrives twice, and publishers of joint keys
only need ``per_joint_keys``."""

from __future__ import annotations

import time
from collections import Counter

from pythonosc.osc_packet import OscPacket

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import encode, load_model
from sonibus.bus.framing import frame

from ..conftest import wait_for
from .test_sink_delivery import commander

RIGHT_ARM = {j for j in load_model("pepper").joint_names if j.startswith("R")}


def seqs(receiver) -> Counter:
    """(address, seq) → how often it arrived (messages sent with ``extra = ["seq"]``)."""
    found: Counter = Counter()
    for datagram in receiver.data():
        for timed in OscPacket(datagram).messages:
            found[(timed.message.address, timed.message.params[-1])] += 1
    return found


def test_a_pattern_selects_joints_out_of_the_frames(net, receivers):
    raw = receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/R*", targets=(raw.target,), extra=("seq",)),
                             name="sound"))
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: len({s for _, s in seqs(raw)}) >= 20, what="20 frames")
    got = seqs(raw)
    assert {address.rsplit("/", 1)[1] for address, _ in got} == RIGHT_ARM
    frames = sorted({s for _, s in got})[1:-1]  # the first and last may be cut by the window
    assert all(got[(f"/pepper/joints/{j}", s)] == 1 for j in RIGHT_ARM for s in frames)
    assert sink.stats["bad"] == 0


def test_a_broad_pattern_gets_each_joint_once_and_the_events(net, receivers):
    raw = receivers()
    net.start(OscSink(OscSinkConfig(subscribe="pepper/**", targets=(raw.target,), extra=("seq",)), name="sound"))
    net.sim("pepper", rate_hz=50)
    bus = commander(net)
    bus.put("pepper/events/custom", {"t": time.time(), "kind": "custom", "level": 2})
    wait_for(lambda: any(a == "/pepper/events/custom" for a, _ in seqs(raw)), what="the event")
    wait_for(lambda: len({s for a, s in seqs(raw) if "/joints/" in a}) >= 20, what="20 frames")
    joints = {key: n for key, n in seqs(raw).items() if "/joints/" in key[0]}
    assert max(joints.values()) == 1, [key for key, n in joints.items() if n > 1][:5]
    assert len({a for a, _ in joints}) == len(load_model("pepper").joint_names)


def test_a_publisher_of_joint_keys_only_needs_per_joint_keys(net, receivers):
    by_frames, by_keys = receivers(), receivers()
    net.start(OscSink(OscSinkConfig(subscribe="toy/joints/*", targets=(by_frames.target,)), name="frames"))
    net.start(OscSink(OscSinkConfig(subscribe="toy/joints/*", targets=(by_keys.target,), per_joint_keys=True),
                      name="keys"))
    src = net.bus("script")
    seq = iter(range(10**6))

    def published() -> None:
        src.put("toy/joints/A", {"t": time.time(), "seq": next(seq), "v": 0.5})

    wait_for(lambda: published() or len(by_keys.items) >= 10,
             what="ten samples through per_joint_keys")
    assert by_frames.items == []


def test_a_frame_of_a_script_is_heard_and_a_stale_one_dropped(net, receivers):
    raw = receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe="toy/joints/*", targets=(raw.target,)), name="sound"))
    src = net.bus("script")
    publisher = src.session.declare_publisher("toy/frame")
    wait_for(lambda: publisher.matching_status.matching, what="the sink's subscription")
    publisher.put(encode(frame(time.time() - 1.0, 1, ["A", "B"], [0.25, 0.5])))
    wait_for(lambda: sink.stats["stale"] == 1, what="the stale frame counted")
    publisher.put(encode(frame(time.time(), 2, ["A", "B"], [0.75, 1.0])))
    wait_for(lambda: len(raw.items) == 2, what="the fresh frame's two samples")
    assert sorted(OscPacket(d).messages[0].message.params[0] for d in raw.data()) == [0.75, 1.0]


def test_a_bundle_joins_a_frame_and_the_derived_values_of_its_seq(net, receivers):
    """As a features node's derived values come: after their frame, before the next one."""
    raw = receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe=("toy/joints/*", "toy/derived/**"), targets=(raw.target,),
                                           bundle=True, extra=("seq",)), name="sound"))
    src = net.bus("script")
    whole, derived = src.stream_publisher("toy/frame"), src.stream_publisher("toy/derived/speed/A")
    wait_for(lambda: whole.matching_status.matching and derived.matching_status.matching, what="the subscriptions")

    def bundles() -> dict[int, list[set[str]]]:
        """seq → the addresses of each bundle that held it."""
        found: dict[int, list[set[str]]] = {}
        for datagram in raw.data():
            messages = [m.message for m in OscPacket(datagram).messages]
            found.setdefault(messages[0].params[-1], []).append({m.address for m in messages})
        return found

    for seq in range(1, 6):
        t = time.time()
        whole.put(encode(frame(t, seq, ["A", "B"], [0.1 * seq, 0.2])))
        wait_for(lambda s=seq: sink.stats["received"] == 3 * s - 1, what=f"frame {seq} at the sink")
        derived.put(encode({"t": t, "seq": seq, "v": 0.5}))
        wait_for(lambda s=seq: sink.stats["received"] == 3 * s, what=f"the derived value of frame {seq}")
    wait_for(lambda: 5 in bundles(), what="the last bundle")
    assert all(bundles()[seq] == [{"/toy/joints/A", "/toy/joints/B", "/toy/derived/speed/A"}]
               for seq in range(1, 6)), bundles()
