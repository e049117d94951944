"""Poison on the bus (issue 13, item 3): a frame holding 1e300, NaN, inf, a finite
but absurd 1e5, or a ``t`` gone back, put on ``pepper/frame`` beside a simulated
Pepper, with a ``features`` node and one OSC sink serving a bundle target and a
plain target. Afterwards both targets get joints and derived values again at
once, and nothing either target ever received is out of its declared range."""

from __future__ import annotations

import logging
import math
import time

import numpy as np
from pythonosc.osc_packet import OscPacket

from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import encode, keys, load_model

from ..conftest import wait_for
from .pd import Datagrams
from .test_sink_delivery import handshake, messages

JOINTS = load_model("pepper").joint_names
WATCHED = ("/pepper/derived/velocity/HeadYaw", "/pepper/derived/qom/Head", "/pepper/derived/qom/Body")
RECOVERY_S = 2.0  # "about a second": a good frame or two after the bad one, on a busy machine


def poison(name: str, now: float) -> dict:
    """The frame ``name`` taken at ``now``: the issue's frame and its kin."""
    head = {"t": now, "seq": 1, "names": ["HeadYaw"]}
    return {
        "1e300": {**head, "v": [1e300]},
        "nan": {**head, "v": [math.nan]},
        "inf": {**head, "v": [math.inf]},
        "1e5": {**head, "v": [1e5]},                                            # finite, within the gate's bound
        "all-1e5": {**head, "names": list(JOINTS), "v": [1e5] * len(JOINTS)},  # arms and hands too
        "t-back": {**head, "t": now - 2.0, "v": [0.5]},                        # time going back
    }[name]


POISONS = {"1e300": "gate", "nan": "gate", "inf": "gate", "1e5": "filter", "all-1e5": "filter", "t-back": "age"}
"""Each poison and what stops it: the bus's gate (counted bad), or the velocity filter (counted rejected)."""


def received(receiver: Datagrams, since: float = 0.0) -> list[tuple[bool, str, list]]:
    """(in a bundle, address, args) of every message that arrived after ``since`` (monotonic)."""
    out = []
    for arrived, dgram in list(receiver.items):
        if arrived >= since:
            bundled = dgram.startswith(b"#bundle")
            out += [(bundled, m.message.address, m.message.params) for m in OscPacket(dgram).messages]
    return out


def out_of_range(messages: list[tuple[bool, str, list]], ranges: dict[str, tuple[np.ndarray, np.ndarray]]) -> list:
    """Derived values that are not finite or not inside the range ``<robot>/info/derived`` declares
    (compared as float32, as OSC carries them)."""
    bad = []
    for _, address, params in messages:
        span = ranges.get(address[1:])
        if span is None:
            continue
        values = np.asarray(params, dtype=np.float32)
        low, high = (np.float32(b) for b in span)
        if not (np.isfinite(values).all() and (values >= low).all() and (values <= high).all()):
            bad.append((address, params))
    return bad


def declared(bus) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each derived key's range as the features node serves it (a hand's: its box)."""
    # (a session just opened may ask before it has learnt the features node's queryable: asked again)
    reply = wait_for(lambda: bus.query(keys.derived_info("pepper")), timeout=10, what="the derived info")[0]
    return {e["key"]: (e["box"]["min"], e["box"]["max"]) if "box" in e else (e["min"], e["max"])
            for e in reply["derived"] if "min" in e}


def test_poison_frames_cost_at_most_a_frame_or_two(net, receivers):
    plain, bundled = receivers(), receivers()
    sink = net.start(OscSink(OscSinkConfig(targets=(plain.target, {"to": bundled.target, "bundle": True})),
                             name="sound"))
    features = net.start(Features(FeaturesConfig(robots="pepper"), name="features"))
    robot = net.sim("pepper", rate_hz=50)
    watch = net.bus("watch")
    wait_for(lambda: all(any(a == w for _, a, _ in received(plain)) for w in WATCHED), timeout=10,
             what="derived values at the plain target")
    ranges = declared(watch)
    # Put from the robot's session: it is known to reach both nodes (their frames come from it).
    stranger = robot.bus.session.declare_publisher(keys.frame("pepper"))

    for name, stopped_by in POISONS.items():
        before = dict(features.stats), dict(sink.stats)
        mark = time.monotonic()
        stranger.put(encode(poison(name, time.time())))

        def recovered(since: float = mark) -> bool:
            derived = {a for _, a, _ in received(plain, since)}
            joints = sum(1 for inside, a, _ in received(bundled, since) if inside and a.startswith("/pepper/joints/"))
            return all(w in derived for w in WATCHED) and joints >= 2 * len(JOINTS)  # two frames' worth

        wait_for(recovered, timeout=RECOVERY_S, what=f"joints and derived values again after the {name} frame",
                 explain=lambda: f"features {features.stats}\nsink {sink.stats}")
        if stopped_by == "gate":
            wait_for(lambda b=before: features.stats["bad"] > b[0]["bad"] and sink.stats["bad"] > b[1]["bad"],
                     what=f"the {name} frame refused by both nodes' gates")
        elif stopped_by == "filter":  # (or skipped as it came: frames after a stall are paced, bus/pacing.py)
            assert (features.stats["rejected"] > before[0]["rejected"]
                    or features.stats["skipped"] > before[0].get("skipped", 0)), features.stats
        else:  # 2 s old: skipped as stale (max_age_ms), never computed
            assert features.stats["stale"] > before[0]["stale"], features.stats
        wrong = out_of_range(received(plain, mark) + received(bundled, mark), ranges)
        assert not wrong, f"after the {name} frame: {wrong[:5]}"

    assert sink.state == features.state == "running"
    everything = received(plain) + received(bundled)
    assert not out_of_range(everything, ranges)
    assert sum(1 for _, a, _ in everything if a.startswith("/pepper/derived/")) > 100
    assert sink.stats["unencodable"] == 0


def test_an_event_osc_cannot_carry_is_left_out_counted_and_warned_about_once(net, receivers, caplog):
    """A string holding NUL is JSON and passes the gate, but no OSC string holds it."""
    caplog.set_level(logging.WARNING)
    raw = receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe="toy/events/*", targets=(raw.target,)), name="sound"))
    src = net.bus("toy")
    handshake(src, "toy/events/hello", raw, {"t": time.time(), "kind": "hello"})
    for _ in range(3):
        src.put("toy/events/speech", {"t": time.time(), "kind": "speech", "text": "a\0b", "state": "started"})
    src.put("toy/events/speech", {"t": time.time(), "kind": "speech", "text": "ab", "state": "done"})
    wait_for(lambda: ("/toy/events/speech", ["ab", "done"]) in messages(raw), what="the good event after them")
    assert [m for m in messages(raw) if m[0] != "/toy/events/hello"] == [("/toy/events/speech", ["ab", "done"])]
    assert sink.stats["unencodable"] == 3 and sink.stats["bad"] == 0
    [warning] = [r.getMessage() for r in caplog.records if "OSC cannot carry" in r.getMessage()]
    assert f"to {raw.target}" in warning and "'/toy/events/speech'" in warning and "\n" not in warning
