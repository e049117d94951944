"""A private JACK server per test (dummy driver: no sound card; ``tests/jackd.py``),
and MIDI ports to talk to the adapters through it."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
import rtmidi

from sonibus.bus import codec, framing, keys

from .. import jackd

jack = jackd.jack  # the fixtures, shared with tests/jack
jack_server = jackd.jack_server


class Reader(jackd.MidiInput):
    """A JACK MIDI input connected to a port; its messages as they came (polled: ``jackd.MidiInput``)."""

    def __init__(self, port: str) -> None:
        super().__init__("reader", connect=port)

    def cc(self, channel: int, number: int) -> list[int]:
        return [m[2] for m in self.messages if m[0] == 0xB0 | (channel - 1) and m[1] == number]


@pytest.fixture
def reader(jack, net) -> Iterator[Any]:
    made: list[Reader] = []

    def connect(port: str) -> Reader:
        made.append(Reader(port))
        return made[-1]

    yield connect
    net.close()  # (the nodes first: see ``writer``)
    for r in made:
        r.close()


# python-rtmidi's JACK calls hold the GIL while libjack waits for the server, and the server waits
# for a cycle of every client, midi-in's among them, whose process callback (Python) needs the GIL:
# a port of the test's own closed while a node of the test's process runs stalled JACK for its 5 s
# timeouts, and then the server did not end (CI). So the test's nodes stop before its ports close.
@pytest.fixture
def writer(jack, net) -> Iterator[Any]:
    """A JACK MIDI output (virtual port 'fader' of client 'surface') for the controller to connect to."""
    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "surface")
    out.open_virtual_port("fader")
    yield out
    net.close()  # (the nodes first: see above)
    out.close_port()
    out.delete()


class FakeRobot:
    """Serves ``<robot>/info`` and puts exact joint values and events on the bus: each
    frame on ``<robot>/frame`` and then per joint, as a robot owner does."""

    def __init__(self, bus: Any, robot: str = "bot", joints: tuple[tuple[str, float, float], ...] = (
            ("A", -2.0, 2.0), ("B", 0.0, 1.0)), behaviors: tuple[str, ...] = ("wave", "nod"),
            rate_hz: float = 50.0) -> None:
        self.bus, self.robot, self.seq = bus, robot, 0
        info = {"robot": robot, "model": "toy", "rate_hz": rate_hz, "behaviors": list(behaviors), "postures": [],
                "adapter": "test", "schema_version": 1, "owner": {"host": bus.host, "node": "fake"},
                "joints": [{"name": n, "unit": "rad", "min": lo, "max": hi, "max_velocity": 1.0}
                           for n, lo, hi in joints]}  # a full robot info: the sinks' gate checks it
        self.queryable = bus.serve(keys.info(robot), lambda q: q.reply(q.key_expr, codec.encode(info),
                                                                       encoding=codec.ENCODING))

    def frame(self, values: dict[str, float], whole: bool = True, joints: bool = True) -> None:
        """One frame of ``values``: whole on ``<robot>/frame`` and on the joint keys; ``whole=False``
        puts the joint keys only (as a script of one's own may), ``joints=False`` the frame only."""
        self.seq += 1
        t = time.time()
        if whole:
            self.bus.put(keys.frame(self.robot), framing.frame(t, self.seq, list(values), list(values.values())))
        for name, value in values.items() if joints else ():
            self.bus.put(keys.joint(self.robot, name), {"t": t, "seq": self.seq, "v": value})

    def joint(self, name: str, value: float) -> None:
        self.frame({name: value})

    def event(self, kind: str, **fields: Any) -> None:
        self.bus.put(keys.event(self.robot, kind), {"t": time.time(), "kind": kind, **fields})


@pytest.fixture
def fake(net) -> Iterator[Any]:
    made: list[FakeRobot] = []

    def make(robot: str = "bot", **options: Any) -> FakeRobot:
        made.append(FakeRobot(net.bus(f"fake-{robot}"), robot, **options))
        return made[-1]

    yield make
    for robot in made:
        robot.queryable.undeclare()
