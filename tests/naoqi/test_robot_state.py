"""The robot's real state everywhere (issue 25, items 2 and 3).

Item 2, a robot that is not there: a ``naoqi`` node whose url points at nothing
listening. ``sonibus nodes``, ``sonibus info``, top's monitor and the web page's
``robots`` message say it is not connected with 0 frames/s; the OSC sink's
receivers (oscdump, and Pd routing ``connection``) and the MIDI sink hear its
state though they start after the owner said it; commands are refused with
``not_connected`` (``sonibus send`` exits 5), ``stop`` is taken and says it did not
reach the robot; the sink's silence warning names the robot first.

Item 3, a frozen robot (naoqi-sim's freeze: the socket stays open, no call is
answered): ``not_answering`` within ``answer_timeout_s``, commands refused with that
code (exit 5) and their ``command`` events ``ok: false``, never ``{"queued": 0}``."""

from __future__ import annotations

import json
import logging
import time

import pytest

from sonibus.adapters.midi import MidiSink, MidiSinkConfig
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.web import WebConfig, WebPages
from sonibus.bus import CommandError, presence, robot_info, send_command
from sonibus.bus.cli.top import GONE, TopApp, robot_cells
from sonibus.bus.monitor import Monitor

from ..conftest import free_port, run_cli, wait_for
from ..jackd import MidiInput, jack  # noqa: F401 (the fixture)
from ..osc.pd import Patch, osc_input, oscdump_lines, printed, start_oscdump, start_pd
from ..wakes import calls
from ..web.browser import Browser
from ..web.conftest import websocket  # noqa: F401 (the fixture)
from .conftest import attach

ALL_NOTES_OFF = [0xB0, 123, 0]


@pytest.fixture
def unreachable(net):
    """A naoqi node whose robot is not there (nothing listens at its url), once it said so."""
    url = f"tcp://127.0.0.1:{free_port()}"
    rig = attach(net, url, wait=False)
    rig.events.wait("connection", state="lost")
    return rig


def test_nodes_info_monitor_and_the_web_page_say_not_connected_and_0_frames(net, unreachable, websocket, tmp_path):  # noqa: F811 (the fixture)
    listed = run_cli("nodes", *net.cli_args())
    [line] = [line for line in listed.stdout.splitlines() if "robot pepper" in line]
    assert " 0 frames/s" in line and "NOT CONNECTED: lost" in line and "Connection refused" in line, line

    shown = run_cli("info", "pepper", *net.cli_args())
    header = shown.stdout.splitlines()[0]
    assert "NOT CONNECTED: lost" in header and " 0 frames/s (of 50 asked)" in header, header
    info = robot_info(unreachable.bus, "pepper")
    assert info["connection"]["state"] == "lost" and info["connection"]["frames_per_s"] == 0

    with Monitor(net.bus("top")) as monitor:
        robot = wait_for(lambda: next((r for r in monitor.snapshot().robots if r.name == "pepper"
                                       and r.connection), None), what="pepper's state in the monitor")
        assert robot.connection["state"] == "lost" and not robot.connected and robot.rate_hz == 0
        cells = robot_cells(robot)
        assert cells[-1].plain.startswith("NOT CONNECTED: lost (") and str(cells[-1].style) == GONE
        assert cells[3].plain == "0"  # frames/s
        TopApp(monitor)._replied("pepper", send_command(unreachable.bus, "pepper", "stop", {}))  # top's `s`
        [stop] = [e for e in monitor.snapshot().events if e.kind == "stop"]
        assert stop.alarm and stop.text.startswith("NOT REACHED: ") and "sent when it answers again" in stop.text

    web = net.start(WebPages(WebConfig(listen="127.0.0.1:0"), name="web"))
    page = websocket(web.url.replace("http://", "ws://") + "/ws")
    shown_robot = wait_for(lambda: next((m["robots"]["pepper"] for m in page.of("robots")
                                         if "pepper" in m["robots"]), None), 10, "pepper on the page")
    assert shown_robot["connected"] is False and shown_robot["connection"]["state"] == "lost"
    assert "Connection refused" in shown_robot["connection"]["error"]

    browser = Browser(tmp_path / "chromium")
    try:  # what the operator sees beside the robot's name
        browser.open(web.url + "/")
        section = '[data-robot="pepper"]'
        browser.wait(lambda: browser.text(f"{section} .robot-rate") == "0 frames/s", "pepper's 0 frames/s")
        assert browser.text(f"{section} .robot-connection") == "not connected: lost"
        assert "Connection refused" in browser.attribute(f"{section} .robot-connection", "title")
        browser.js("sonibus.stop()")  # the page's STOP: taken, and said not to have reached the robot
        browser.wait(lambda: "✗ pepper: not reached" in (browser.text("#status") or ""), "the STOP's outcome")
    finally:
        browser.quit()


def test_commands_are_refused_not_connected_and_stop_says_it_did_not_reach_the_robot(net, unreachable):
    said = run_cli("send", "pepper", "say", "hello", *net.cli_args())
    assert said.returncode == 5, said
    assert "not connected" in said.stderr and said.stdout == "", said
    event = unreachable.events.wait("command", verb="say")
    assert event["ok"] is False and "not connected" in event["error"]
    with pytest.raises(CommandError) as refused:
        send_command(unreachable.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.1]})
    assert refused.value.code == "not_connected"

    stopped = run_cli("send", "pepper", "stop", *net.cli_args())
    assert stopped.returncode == 5, stopped
    result = json.loads(stopped.stdout)
    assert result["reached"] is False and result["connection"] == "lost" and result["pending"] is True
    assert "did not reach robot 'pepper'" in stopped.stderr


def test_sinks_started_after_the_owner_hear_its_state_and_the_silence_names_the_robot(
        jack, net, unreachable, spawn, tmp_path, monkeypatch, caplog):  # noqa: F811 (jack: the fixture)
    monkeypatch.setattr(presence, "SILENCE_S", 1.0)
    caplog.set_level(logging.WARNING, logger="sonibus")
    dump_port, pd_port = free_port(), free_port()
    dump = start_oscdump(spawn, dump_port)
    patch = Patch()  # as patches/pd/sonibus-events.pd routes a connection event
    patch.chain(osc_input(patch, pd_port), patch.obj("route", "pepper"), patch.obj("route", "events"),
                patch.obj("route", "connection"), patch.obj("print", "CONNECTION"))
    pd = start_pd(spawn, tmp_path, patch)
    net.start(OscSink(OscSinkConfig(subscribe=("pepper/joints/*", "pepper/events/*"),
                                    targets=(f"127.0.0.1:{dump_port}", f"127.0.0.1:{pd_port}")), name="sound"))
    midi = Synth()  # a port the sink connects to as it starts: nothing it sends is missed
    try:
        net.start(MidiSink(MidiSinkConfig(api="jack", connect="synth:din"), name="daw"))
        heard(dump, pd, midi, caplog)
    finally:
        midi.close()


class Synth(MidiInput):
    """A JACK MIDI input of its own (``synth:din``), its messages as they came (polled: ``MidiInput``)."""

    def __init__(self) -> None:
        super().__init__("synth", virtual="din")


def silence(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if "none of its data arrived" in r.getMessage()]


def heard(dump, pd, midi, caplog):
    wait_for(lambda: [line for line in oscdump_lines(dump) if "/pepper/events/connection" in line], 10,
             "the robot's state at oscdump", lambda: "\n".join(oscdump_lines(dump)))
    wait_for(lambda: printed(pd, "CONNECTION"), 10, "the robot's state in Pd")
    wait_for(lambda: ALL_NOTES_OFF in midi.messages, 10, "all notes off at the MIDI port")
    wait_for(lambda: len(silence(caplog)) >= 2, 10, "each sink's silence warning")
    silent = silence(caplog)
    events = [line for line in oscdump_lines(dump) if "/pepper/events/connection" in line]
    assert len(events) == 1 and events[0].endswith('s "lost"'), events  # once, never "connected"
    assert printed(pd, "CONNECTION") == ["lost"]
    assert not [line for line in oscdump_lines(dump) if "/joints/" in line], "0 frames"
    assert [m for m in midi.messages if m != ALL_NOTES_OFF] == [], "no joint CC: 0 frames"

    assert sorted(w.split(":")[0] for w in silent) == ["daw", "sound"], silent  # once each
    for warning in silent:
        causes = [warning.index(cause) for cause in ("NOT CONNECTED: lost", "access control", "namespace")]
        assert causes == sorted(causes), warning


def test_a_frozen_robot_is_not_answering_and_its_commands_are_refused(net, rig):
    r = rig(answer_timeout_s=0.5, connect_timeout_s=8.0)  # (not answering for 8 s before the link is dropped)
    r.events.wait("connection", state="connected")
    send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.3]})
    r.fake.freeze()
    with pytest.raises(CommandError) as at_once:  # frozen a moment ago: still "connected", but not answering
        send_command(r.bus, "pepper", "say", {"text": "anyone?"})
    assert at_once.value.code == "not_answering", at_once.value
    frozen = r.events.wait("connection", timeout=3.0, state="not_answering")
    assert "no frame" in frozen["error"]
    assert robot_info(r.bus, "pepper")["connection"]["state"] == "not_answering"

    with pytest.raises(CommandError) as refused:
        send_command(r.bus, "pepper", "say", {"text": "hi"})
    assert refused.value.code == "not_answering" and "does not answer" in refused.value.message
    events = wait_for(lambda: (found := r.events.find("command", verb="say"))[1:] and found, 5, "both says' events")
    assert [e["ok"] for e in events] == [False, False] and all("not answer" in e["error"] for e in events)
    stop = send_command(r.bus, "pepper", "stop", {}, timeout=5.0)
    assert stop["reached"] is False and stop["connection"] == "not_answering" and stop["pending"] is True, stop
    said = run_cli("send", "pepper", "say", "hi", *net.cli_args())  # (not answering, or lost by now on a busy machine)
    assert said.returncode == 5 and "nothing was sent" in said.stderr and said.stdout == "", said

    assert not r.fake.engine.halted, "the robot did the stop while frozen"
    r.fake.resume()
    wait_for(lambda: r.events.find("connection", state="connected")[1:], 10, "answering again")
    wait_for(lambda: r.fake.engine.halted, 5, "the stop asked for while frozen, done once it answers")
    wait_for(lambda: not r.adapter.stop_pending, 5, "the stop no longer pending")
    assert "queued" in send_command(r.bus, "pepper", "say", {"text": "hi"})  # (behind "anyone?", sent and held)


def test_a_sink_hears_each_state_of_a_robot_once(net, fakes, spawn):
    """Issue 29, item 10: ``/pepper/events/connection "connected"`` arrived twice at start: the
    owner's event, and the sink's own when the robot's token appeared. Now the sink says the
    state its owner's info gives, and a state already said is not said again."""
    port = free_port()
    dump = start_oscdump(spawn, port)
    sink = net.start(OscSink(OscSinkConfig(subscribe=("pepper/events/*",), targets=(f"127.0.0.1:{port}",)),
                             name="sound"))
    fake = fakes()
    r = attach(net, fake.url)
    r.events.wait("connection", state="connected")
    wait_for(lambda: not sink._presence.unsaid and "pepper" in sink._presence.on_bus, 10,
             "the sink's own word on pepper's state")
    r.bus.put("pepper/events/marker", {"t": time.time(), "kind": "marker"})  # after whatever the sink queued
    wait_for(lambda: [line for line in oscdump_lines(dump) if "/pepper/events/marker" in line], 10, "the marker")
    states = [line.rsplit(" ", 1)[1] for line in oscdump_lines(dump) if "/pepper/events/connection" in line]
    assert states[-1] == '"connected"' and states.count('"connected"') == 1, states  # ("connecting" before, or not:
    assert set(states) <= {'"connecting"', '"connected"'}, states                   # the sink may hear it or not)


def test_the_not_answering_watch_wakes_once_a_timeout_not_ten_times_a_second(net, rig):
    """While frames flow, the owner's watch of a silent robot sleeps ``answer_timeout_s`` after the
    last frame it saw (it woke every 0.1 s); a robot that freezes is still not answering in time."""
    r = rig(answer_timeout_s=1.0, connect_timeout_s=8.0)
    r.events.wait("connection", state="connected")
    # its wake-ups counted where it wakes (a thread's context switches count its GIL waits too)
    counted = calls({"due_in": (r.adapter.connection, "due_in")}, 2.0)
    assert counted["due_in"] <= 4, counted  # (1-3 measured; before: 20-24)
    r.fake.freeze()
    frozen = r.events.wait("connection", timeout=5.0, state="not_answering")
    assert "no frame" in frozen["error"]
