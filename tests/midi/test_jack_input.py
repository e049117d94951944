"""``midi-in`` on JACK: a controller in a process of its own (``surface.py``) connects,
floods and is killed; the node stays up, counts what it dropped, says the controller
left, and takes the next controller of that name."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import jack as python_jack

from sonibus.adapters.midi import MidiController, MidiControllerConfig
from sonibus.bus import decode

from ..conftest import wait_for

SURFACE = str(Path(__file__).with_name("surface.py"))
HEY = "animations/Stand/Gestures/Hey_1"


def test_a_controller_that_floods_and_vanishes_leaves_the_node_up_for_the_next(net, jack, spawn, caplog):
    net.sim("pepper", rate_hz=50)
    flood = spawn(sys.executable, SURFACE, "flood", "500000", collect=True)  # at most 9 s at 56,000/s
    wait_for(lambda: "ready" in flood.lines, 10, "the first controller's port")
    node = net.start(MidiController(MidiControllerConfig(
        api="jack", connect="surface:fader", queue=256,
        notes=({"note": 60, "robot": "pepper", "behavior": HEY},)), name="surface-in"))
    _, events = net.bus("watch").subscribe("pepper/events/behavior")
    wait_for(lambda: "connected" in flood.lines, 10, "the node to connect to the first controller")
    wait_for(lambda: node.stats["dropped"] > 0, 10, "the node's queue to overflow in the flood")
    flood.popen.send_signal(signal.SIGKILL)  # mid-flood, as a controller unplugged or crashed
    flood.popen.wait(5)

    wait_for(lambda: node.stats["controllers_left"] == 1, 15, "the node to see the controller leave")
    # (counted, then said, on the node's watch thread: the words may come a moment after the count)
    wait_for(lambda: "controller 'surface:fader' left surface-in:sonibus-in, waiting for a port matching"
             in caplog.text, 5, "the node to say the controller left")
    # every message heard is handled or counted dropped, none lost unsaid
    wait_for(lambda: node.stats["unmapped"] + node.stats["dropped"] == node._jack.heard, 5, "the queue drained")
    assert node.stats["received"] == node.stats["unmapped"]
    assert node.state == "running" and not node.failure

    again = spawn(sys.executable, SURFACE, "note", "60", collect=True)
    wait_for(lambda: "connected" in again.lines, 10, "the node to connect to the new controller")
    got: list[dict] = []

    def started() -> bool:
        while (item := events.get(timeout=0)) is not None:
            got.append(decode(item[1]))
        return any(e["name"] == HEY and e["state"] == "started" for e in got)

    wait_for(started, 10, "the new controller's key to run the behavior")
    assert node.stats["controllers_left"] == 1 and node.state == "running"


def test_the_jack_server_going_away_fails_the_node_in_one_line(net, jack_server):
    name, server = jack_server
    node = net.start(MidiController(MidiControllerConfig(api="jack"), name="surface-in"))
    server.stop(timeout=5)
    wait_for(lambda: node.failure, 5, "the node to fail")
    assert node.state == "failed" and f"JACK server '{name}' went away" in node.failure
    assert len(node.failure.splitlines()) == 1
    node.stop()  # (closing a client whose server is gone returns)


def test_a_port_that_goes_while_jack_lists_the_ports_leaves_the_node_up(net, jack, spawn, monkeypatch):
    """python-jack lists port names, then looks each one up: a controller that goes in between
    raises JackError("Port '…' not available") from the listing (a full run's node died of it)."""
    first = spawn(sys.executable, SURFACE, "note", "60", collect=True)
    wait_for(lambda: "ready" in first.lines, 10, "the first controller's port")
    node = net.start(MidiController(MidiControllerConfig(api="jack", connect="surface:fader"), name="surface-in"))
    wait_for(lambda: "connected" in first.lines, 10, "the node to connect to the first controller")
    client = node._jack.client
    real = client.get_ports
    vanished: list[bool] = []

    def vanishing(*args, **kwargs):
        if not vanished:
            vanished.append(True)
            raise python_jack.JackError("Port 'surface:fader' not available")
        return real(*args, **kwargs)

    monkeypatch.setattr(client, "get_ports", vanishing)
    first.popen.send_signal(signal.SIGKILL)
    first.popen.wait(5)
    wait_for(lambda: vanished, 10, "the node to list the ports once the controller left")
    again = spawn(sys.executable, SURFACE, "note", "60", collect=True)
    wait_for(lambda: "connected" in again.lines, 10, "the node to connect to the next controller")
    assert node.state == "running" and not node.failure
