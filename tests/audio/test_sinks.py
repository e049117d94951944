"""Sinks take audio only where a pattern names it: ``pepper/**`` brings none to an
OSC target, and a sink that cannot carry audio refuses a pattern that names it."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from sonibus.adapters.foxglove.server import FoxgloveConfig
from sonibus.adapters.midi.config import MidiSinkConfig
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import ConfigError, encode, keys
from sonibus.bus.audio import AudioChunk
from sonibus.bus.node import AUDIO
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Streams

from ..conftest import free_port, require_tool, wait_for


def chunk(seq: int) -> bytes:
    return encode(AudioChunk.from_samples(time.time(), seq, 16000, np.full((160, 4), 0.1)).message())


def test_an_osc_sink_on_pepper_everything_sends_events_but_no_audio(net, spawn):
    oscdump = require_tool("oscdump", "liblo-tools")
    port = free_port(socket.SOCK_DGRAM)
    receiver = spawn(oscdump, "-L", str(port), collect=True)
    sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/**", targets=(f"127.0.0.1:{port}",)), name="sound"))
    robot = net.bus("robot")
    mic = robot.stream_publisher(keys.audio("pepper", "mic"), AUDIO)
    status = robot.stream_publisher(keys.event("pepper", "status"))
    wait_for(lambda: status.matching_status.matching, what="the sink's subscription to pepper/**")
    # pepper/** does not even subscribe to audio: a robot's microphones, published only while
    # someone listens, stay off for it
    assert not mic.matching_status.matching
    published = 0

    def events_arrived() -> bool:  # each event follows audio chunks on the same link
        nonlocal published
        for _ in range(5):
            mic.put(chunk(published))
            published += 1
        robot.put(keys.event("pepper", "status"), {"t": time.time(), "kind": "status", "n": published})
        return sum("/events/status" in line for line in receiver.lines) >= 5

    wait_for(events_arrived, what="5 events at the OSC target", explain=lambda: "\n".join(receiver.lines))
    assert not [line for line in receiver.lines if "mic" in line or "audio" in line], receiver.lines
    assert sink.stats["bad"] == 0 and sink.stats["received"] <= published // 5, sink.stats


def test_streams_bring_audio_only_to_a_pattern_that_names_it(net):
    listener, robot = net.bus("listener"), net.bus("robot")
    named, broad = SampleQueue(), SampleQueue()
    streams = [Streams(listener, ["*/audio/*"], named), Streams(listener, ["pepper/**"], broad)]
    try:
        mic = robot.stream_publisher(keys.audio("pepper", "mic"), AUDIO)
        status = robot.stream_publisher(keys.event("pepper", "status"))                # only pepper/** wants it
        wait_for(lambda: mic.matching_status.matching and status.matching_status.matching, what="the subscriptions")
        mic.put(chunk(0))
        status.put(encode({"t": time.time(), "kind": "status"}))
        got = wait_for(lambda: named.get(0.1), what="the chunk on */audio/*")
        message = streams[0].incoming(*got).message
        assert AudioChunk.of(message).samples().shape == (160, 4)
        assert wait_for(lambda: broad.get(0.1), what="the event on pepper/**")[0] == "pepper/events/status"
        mic.put(chunk(1))
        status.put(encode({"t": time.time(), "kind": "status"}))
        wait_for(lambda: named.get(0.1), what="the second chunk")                  # it came to the listener...
        assert wait_for(lambda: broad.get(0.1), what="the second event")[0] == "pepper/events/status"
        assert broad.get(0) is None                                                # ...not through pepper/**
    finally:
        for stream in streams:
            stream.undeclare()


@pytest.mark.parametrize(("config", "sink"), [(OscSinkConfig, "an OSC sink"), (MidiSinkConfig, "a MIDI sink"),
                                              (FoxgloveConfig, "the foxglove adapter")])
def test_a_sink_that_cannot_carry_audio_refuses_a_pattern_naming_it(config, sink):
    for pattern in ("pepper/audio/mic", "*/audio/*"):
        with pytest.raises(ConfigError) as caught:
            config(subscribe=("pepper/joints/*", pattern))
        assert str(caught.value) == (f"key 'subscribe': '{pattern}' is audio, which {sink} cannot carry — leave it "
                                     "out (the jack adapter plays audio; the recorder records it)")
    assert config(subscribe="pepper/**").subscribe == ("pepper/**",)
