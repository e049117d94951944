"""A private JACK server per test (dummy driver: no sound card), and MIDI ports to
talk to the adapters through it."""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import rtmidi

from sonibus.bus import codec, keys, messages

from ..conftest import Process, require_tool, wait_for


def _jack_up() -> bool:
    try:
        probe = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "probe")
    except rtmidi.SystemError:
        return False
    probe.delete()
    return True


@pytest.fixture
def jack(spawn, monkeypatch) -> Iterator[str]:
    """The name of a running JACK server, made the default for this test; always stopped."""
    jackd = require_tool("jackd", "jackd2")
    name = f"sonibus-{uuid.uuid4().hex[:8]}"
    monkeypatch.setenv("JACK_DEFAULT_SERVER", name)
    monkeypatch.setenv("JACK_NO_START_SERVER", "1")
    server: Process = spawn(jackd, "--no-realtime", "-n", name, "-d", "dummy", "-r", "48000", "-p", "256")
    wait_for(lambda: server.popen.poll() is not None or _jack_up(), timeout=10, what=f"jackd -n {name}")
    if server.popen.poll() is not None:
        _, err = server.popen.communicate()
        pytest.fail(f"jackd -n {name} ended at start: {err[-500:]}")
    yield name
    server.stop(timeout=5)
    for leftover in Path("/dev/shm").glob(f"jack_sem.*_{name}_*"):  # jackd 1.9 leaves its clients' semaphores
        leftover.unlink(missing_ok=True)


class Reader:
    """A JACK MIDI input connected to a port; messages gathered as they come."""

    def __init__(self, port: str) -> None:
        self.port = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, "reader")
        names = self.port.get_ports()
        wanted = [i for i, n in enumerate(names) if port in n]
        assert wanted, f"no port '{port}' among {names}"
        self.messages: list[list[int]] = []
        self.port.set_callback(lambda event, data: self.messages.append(event[0]))
        self.port.open_port(wanted[0], "in")

    def cc(self, channel: int, number: int) -> list[int]:
        return [m[2] for m in self.messages if m[0] == 0xB0 | (channel - 1) and m[1] == number]

    def close(self) -> None:
        self.port.close_port()
        self.port.delete()


@pytest.fixture
def reader(jack) -> Iterator[Any]:
    made: list[Reader] = []

    def connect(port: str) -> Reader:
        made.append(Reader(port))
        return made[-1]

    yield connect
    for r in made:
        r.close()


@pytest.fixture
def writer(jack) -> Iterator[Any]:
    """A JACK MIDI output (virtual port 'fader' of client 'surface') for the controller to connect to."""
    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "surface")
    out.open_virtual_port("fader")
    yield out
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
            self.bus.put(keys.frame(self.robot), messages.frame(t, self.seq, list(values), list(values.values())))
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
