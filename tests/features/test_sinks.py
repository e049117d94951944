"""Derived values reach sound tools through the existing sinks, scaled by the
ranges on ``<robot>/info/derived``: OSC (read from a UDP socket) and MIDI (a
real JACK port), also when the features node starts after the sink."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.midi import MidiSink, MidiSinkConfig
from sonibus.adapters.midi.mapping import MAX7, scale
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import ConfigError, keys, robot_info, send_command

from ..conftest import wait_for
from ..osc.pd import Datagrams
from .test_processor import HEY, collect, pump, start


class Normalized:
    """OSC messages (sent with ``extra = ["seq"]``) checked against the derived samples on the bus."""

    def __init__(self, receiver: Datagrams, derived: list, ranges: dict[str, tuple[float, float]]) -> None:
        self.receiver, self.derived, self.ranges = receiver, derived, ranges

    def messages(self) -> list[tuple[str, list, bool | None]]:
        """Derived values as (key, values, whether they are the raw value normalized — None if the raw
        one was not seen on the bus, or looks the same normalized: 0 for a speed)."""
        raw = {(k, m["seq"]): m["v"] for k, m in list(self.derived)}
        out = []
        for message in map(OscMessage, self.receiver.data()):
            *values, seq = message.params
            key = message.address[1:]
            if "/derived/" not in key:
                continue
            low, high = self.ranges[key.split("/", 2)[2]]
            found = raw.get((key, seq))
            ok = None
            if found is not None:
                normalized = np.clip((np.atleast_1d(found) - low) / (high - low), 0.0, 1.0)
                if not np.allclose(normalized, found, atol=1e-6):
                    ok = bool(np.allclose(values, normalized, atol=1e-6))
            out.append((key, values, ok))
        return out


@pytest.mark.parametrize("features_first", [True, False], ids=["features-first", "sink-first"])
def test_osc_sends_derived_values_normalized_by_their_ranges(net, features_first):
    net.sim("pepper", rate_hz=50)
    watch = net.bus("watch")
    if features_first:  # and serving pepper/info/derived before the sink asks for pepper's info
        start(net, robots="pepper")
        wait_for(lambda: watch.query(keys.derived_info("pepper"), timeout=0.5), what="pepper/info/derived")
    receiver = Datagrams()
    try:
        sink = net.start(OscSink(OscSinkConfig(subscribe=("pepper/joints/HeadYaw", "pepper/derived/**"),
                                               targets=(receiver.target,), values="normalized", extra=("seq",)),
                                 name="sound"))
        if not features_first:  # the sink has the robot's info before any derived range exists
            wait_for(lambda: sink.stats["sent"] >= 5, what="normalized joints")
            start(net, robots="pepper")
        ranges = {d["name"]: (d["min"], d["max"]) for d in wait_for(
            lambda: watch.query(keys.derived_info("pepper"), timeout=0.5), what="pepper/info/derived")[0]["derived"]}
        subscriber, derived = collect(watch, "pepper/derived/**")
        wait_for(lambda: robot_info(watch, "pepper", timeout=0.5), what="pepper/info")
        send_command(watch, "pepper", "behavior/run", {"name": HEY})
        check = Normalized(receiver, derived, ranges)
        wait_for(lambda: any(k == "pepper/derived/qom/RArm" and ok and v[0] > 0.02 for k, v, ok in check.messages()),
                 what="the right arm's QoM, normalized")
        wait_for(lambda: {k.split("/")[2] for k, _, ok in check.messages() if ok} ==
                 {"velocity", "hand", "hand_speed", "qom"}, what="every feature normalized")
        subscriber.undeclare()
    finally:
        receiver.close()
    derived_messages = check.messages()  # never raw, not even while the sink learns the ranges (it was, ~2 s)
    assert all(ok is not False for _, _, ok in derived_messages), derived_messages
    assert all(0.0 <= x <= 1.0 for _, v, _ in derived_messages for x in v)


def test_midi_maps_a_derived_value_to_a_controller(net, owner, reader):
    joints = [{"name": "Elbow", "unit": "rad", "min": -2.0, "max": 2.0, "max_velocity": 4.0, "chain": "Arm"}]
    fake = owner("bot", {"robot": "bot", "model": "robbie", "rate_hz": 100.0, "joints": joints})
    sink = net.start(MidiSink(MidiSinkConfig(api="jack", subscribe=("bot/joints/*", "bot/derived/**"), auto_map=False,
                                             map=({"key": "bot/derived/qom/Arm", "cc": 7},)), name="daw"))
    midi = reader("daw:sonibus")
    pump(fake, lambda k: {"Elbow": 0.0}, lambda: sink.estimated_rate > 0, "the sink knows bot (no derived yet)")
    watch = net.bus("watch")
    subscriber, derived = collect(watch, "bot/derived/qom/Arm")
    start(net, robots="bot")
    pump(fake, lambda k: {"Elbow": 1.5 * math.sin(k * 0.1)}, lambda: max(midi.cc(1, 7), default=0) >= 10,
         "the arm's QoM on CC 7", timeout=8)
    subscriber.undeclare()
    possible = {scale(m["v"], 0.0, 4.0, MAX7) for _, m in derived}  # qom/Arm: 0..1 × 4 rad/s
    assert set(midi.cc(1, 7)) <= possible
    assert all(m[1] == 7 for m in midi.messages if m[0] & 0xF0 == 0xB0)  # nothing auto-mapped


def test_midi_map_entries_take_derived_keys():
    assert MidiSinkConfig(map=({"key": "pepper/derived/qom/RArm", "cc": 7},)).entries
    for key in ("pepper/derived/qom", "pepper/joints/qom/RArm", "pepper/derived/*/RArm"):
        with pytest.raises(ConfigError, match=r"is not a joint key .* or a derived key"):
            MidiSinkConfig(map=({"key": key, "cc": 7},))
