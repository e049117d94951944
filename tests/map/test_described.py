"""A map's output is a signal described like a robot's derived values: sinks that need a
range (OSC ``normalized``, MIDI, OSCQuery) learn it from ``<map node>/info/derived`` alone,
the map node being no robot (no claim, no ``<node>/info`` of its own)."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from pythonosc.osc_message import OscMessage

from sonibus.adapters.midi import MidiSink, MidiSinkConfig
from sonibus.adapters.osc import OscSink, OscSinkConfig

from ..conftest import wait_for
from ..features.conftest import model_info
from ..midi.conftest import FakeRobot
from ..osc.test_sink_delivery import messages
from ..oscquery.conftest import serve
from .conftest import map_node, pose
from .test_sinks import TEXT


@contextmanager
def frames(robot, yaw: float = 0.5) -> Iterator[None]:
    """The robot's frames at 50 Hz, HeadYaw at ``yaw``, until the block ends."""
    stop = threading.Event()

    def feed() -> None:
        while not stop.is_set():
            robot.frame(time.time(), pose(HeadYaw=yaw))
            stop.wait(0.02)

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        yield
    finally:
        stop.set()
        feeder.join()


def test_osc_raw_sends_a_maps_output_in_its_own_unit(net, owner, receivers):
    pepper = owner("pepper", model_info("pepper"))
    raw = receivers()
    net.start(OscSink(OscSinkConfig(subscribe="sound/derived/**", targets=(raw.target,)), name="osc"))
    map_node(net, TEXT)
    with frames(pepper):
        wait_for(lambda: messages(raw, "/sound/derived/map/head"), timeout=10, what="the map's output over OSC")
    assert messages(raw, "/sound/derived/map/head")[0][1] == [95.25]


def test_osc_normalized_scales_a_maps_output_by_its_declared_range_at_once(net, owner, receivers):
    """0.5 rad → 95.25 of 0..127 → 0.75; not held back UNDESCRIBED_WAIT_S (3 s) and then sent raw."""
    pepper = owner("pepper", model_info("pepper"))
    raw = receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe="sound/derived/**", targets=(raw.target,),
                                           values="normalized"), name="osc"))
    map_node(net, TEXT)
    with frames(pepper):
        start = time.monotonic()
        wait_for(lambda: messages(raw, "/sound/derived/map/head"), timeout=10, what="the map's output over OSC")
        took = time.monotonic() - start
    first = messages(raw, "/sound/derived/map/head")[0]
    assert first[1] == [0.75], (first, dict(sink.stats))
    assert took < 2.5, took  # (described, not waited out: UNDESCRIBED_WAIT_S is 3 s)


MIDI_TEXT = TEXT.replace("head", "cutoff").replace("pepper/joints/HeadYaw", "bot/joints/A").replace(
    "from = [-1, 1]", "from = [-2, 2]").replace("to = [0, 127]", "to = [0, 200]").replace('"cc"', '"Hz"')


def test_midi_plays_a_maps_output_on_its_cc_scaled_by_the_maps_range(net, reader):
    """Through a real JACK MIDI port: A = 1 rad → 150 Hz of 0..200 → CC 74 at 95 (not 127, clamped raw)."""
    daw = net.start(MidiSink(MidiSinkConfig(api="jack", subscribe=("sound/derived/**",), auto_map=False,
                                            map=({"key": "sound/derived/map/cutoff", "cc": 74},)), name="daw"))
    midi = reader("daw:sonibus")
    bot = FakeRobot(net.bus("fake-bot"))
    try:
        map_node(net, MIDI_TEXT)

        def played() -> list[int]:
            bot.frame({"A": 1.0, "B": 0.0})
            return midi.cc(1, 74)
        wait_for(played, timeout=10, what="the map's output on CC 74", explain=lambda: dict(daw.stats))
    finally:
        bot.queryable.undeclare()
    assert set(midi.cc(1, 74)) == {95}, midi.cc(1, 74)


def test_oscquery_serves_a_maps_output_with_its_range_and_drops_it_when_the_node_goes(net, owner, websocket):
    """Listed at /sound/derived/map/head with its RANGE and current VALUE, streamed to a client that
    LISTENs; PATH gone when the map node stops."""
    pepper = owner("pepper", model_info("pepper"))
    served = serve(net)
    node = map_node(net, TEXT)
    with frames(pepper):
        described = served.wait_node("/sound/derived/map/head")
        assert described["RANGE"] == [{"MIN": 0, "MAX": 127}], described
        assert wait_for(lambda: served.json("/sound/derived/map/head?VALUE").get("VALUE") == [95.25],
                        what="the map's value served")
        client = websocket(served.url)
        client.send({"COMMAND": "LISTEN", "DATA": "/sound/derived/map/head"})
        streamed = wait_for(lambda: [OscMessage(m) for m in list(client.messages) if isinstance(m, bytes)],
                            what="the map's output streamed to a LISTENer")
        assert (streamed[0].address, streamed[0].params) == ("/sound/derived/map/head", [95.25])
        node.stop()
        wait_for(lambda: served.get("/sound").status_code == 404, what="the map node's paths removed")
