"""The ``foxglove`` adapter seen by Foxglove's own client, not ours: @foxglove/ws-protocol's
``FoxgloveClient`` (the npm package Lichtblick and older Foxglove apps use) run with node,
offering only its subprotocol ``foxglove.websocket.v1`` (issue 26, item 7): it connects
(foxglove-sdk's server answered 400), sees the first message of a channel made after it
connected (a robot's first event, in the Log panel's ``<robot>/log``), and over many
sessions none of its subscriptions to channels made while it connects is refused."""

from __future__ import annotations

import json
import os
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from sonibus.adapters.foxglove.hub import HISTORY
from sonibus.adapters.foxglove.server import FoxgloveConfig, FoxgloveServer

from ..conftest import Network, wait_for

CLIENT = Path(__file__).resolve().parent / "js" / "client.js"


class Official:
    """``node client.js``: its events (JSON lines) as they come; a line on stdin ends a session."""

    def __init__(self, port: int, pattern: str, sessions: int = 1, subscribe_later: bool = False) -> None:
        if not (CLIENT.parent / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
            pytest.fail(f"the official client is not installed: run `npm ci --prefix {CLIENT.parent}` "
                        "(scripts/test-tools.sh does)")
        self.popen = subprocess.Popen(["node", str(CLIENT), f"ws://127.0.0.1:{port}", pattern, str(sessions)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True, env={**os.environ, "SUBSCRIBE_LATER": "1" if subscribe_later else ""})
        self.events: list[dict[str, Any]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.popen.stdout:
            self.events.append(json.loads(line))

    def of(self, ev: str, since: int = 0) -> list[dict[str, Any]]:
        return [e for e in self.events[since:] if e["ev"] == ev]

    def next_session(self) -> None:
        self.popen.stdin.write("\n")
        self.popen.stdin.flush()

    def subscribe(self) -> None:
        """Take the subscriptions held back (``subscribe_later``)."""
        self.popen.stdin.write("subscribe\n")
        self.popen.stdin.flush()

    def close(self) -> str:
        if self.popen.poll() is None:
            self.popen.kill()
        self.popen.wait(5)
        return self.popen.stderr.read()


@pytest.fixture
def official():
    started: list[Official] = []

    def start(*args: Any) -> Official:
        started.append(Official(*args))
        return started[-1]

    yield start
    for client in started:
        client.close()


def event(kind: str, **fields: Any) -> dict[str, Any]:
    return {"t": time.time(), "kind": kind, **fields}


def test_the_official_client_offering_foxglove_websocket_v1_sees_the_first_message_of_a_new_channel(net: Network,
                                                                                                   official):
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    client = official(server.port, "^pepper/(log|events/behavior)$")
    wait_for(lambda: client.of("open") and client.of("serverInfo"), 15, "the official client connected",
             lambda: str(client.events))
    assert client.of("open")[0]["protocol"] == "foxglove.websocket.v1"
    assert client.of("serverInfo")[0]["name"] == "sonibus"
    bus = net.bus("robot")
    bus.put("pepper/events/behavior", event("behavior", name="animations/Hey_1", state="started"))
    wait_for(lambda: len(client.of("message")) >= 2, 10, "the first messages of pepper/log and "
             "pepper/events/behavior", lambda: str(client.events))
    texts = {m["topic"]: json.loads(m["text"]) for m in client.of("message")}
    assert texts["pepper/log"]["message"] == "behavior animations/Hey_1 started"
    assert texts["pepper/events/behavior"]["state"] == "started"
    assert not client.of("status") and not client.of("error")


def test_a_subscription_taken_after_several_events_gets_every_one_since_the_advertisement(net: Network, official):
    """Issue 33: a viewer subscribes a moment after it hears of a channel; a behavior's ``started``
    and the next event came in that moment, and the Log panel showed only the second (the
    channel's latest). Now it gets both, in order, then the live ones; a state channel (the
    frame) still gives its latest only."""
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    client = official(server.port, "^pepper/(log|events/behavior)$", 1, True)
    watcher = official(server.port, "^pepper/log$")  # (subscribes at once: tells when the server logged both)
    wait_for(lambda: client.of("serverInfo") and watcher.of("serverInfo"), 15, "the official clients connected",
             lambda: str(client.events + watcher.events))
    bus = net.bus("robot")
    name = "animations/Hey_1"
    bus.put("pepper/events/behavior", event("behavior", name=name, state="started"))
    bus.put("pepper/events/behavior", event("behavior", name=name, state="stopped"))
    wait_for(lambda: {a["topic"] for a in client.of("advertise")} >= {"pepper/log", "pepper/events/behavior"}, 10,
             "both channels advertised", lambda: str(client.events))
    wait_for(lambda: len(watcher.of("message")) == 2, 10, "both events on pepper/log", lambda: str(watcher.events))
    client.subscribe()
    bus.put("pepper/events/behavior", event("behavior", name="animations/Wave", state="started"))

    def log_lines() -> list[str]:
        return [json.loads(m["text"])["message"] for m in client.of("message") if m["topic"] == "pepper/log"]

    wait_for(lambda: len(log_lines()) >= 3, 10, "three lines in the Log channel", lambda: str(client.events))
    assert log_lines() == [f"behavior {name} started", f"behavior {name} stopped",
                           "behavior animations/Wave started"]
    states = [json.loads(m["text"])["state"] for m in client.of("message") if m["topic"] == "pepper/events/behavior"]
    assert states == ["started", "stopped", "started"]
    assert not client.of("status") and not client.of("error")


def test_what_an_event_channel_keeps_for_a_late_subscription_is_bounded(net: Network, official):
    """A flood of events before the subscription: the newest ``HISTORY`` of them, in order."""
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    client = official(server.port, "^pepper/events/behavior$", 1, True)
    watcher = official(server.port, "^pepper/events/behavior$")
    wait_for(lambda: client.of("serverInfo") and watcher.of("serverInfo"), 15, "the official clients connected")
    bus = net.bus("robot")
    sent = HISTORY + 44
    for n in range(sent):  # (in steps of 50 taken: a node's queue is no place to test a flood)
        bus.put("pepper/events/behavior", event("behavior", name=f"b{n}", state="started"))
        if n % 50 == 49 or n == sent - 1:
            wait_for(lambda n=n: len(watcher.of("message")) == n + 1, 15, f"{n + 1} events logged",
                     lambda: str(len(watcher.of("message"))))
    client.subscribe()
    wait_for(lambda: len(client.of("message")) >= HISTORY, 10, "the kept events", lambda: str(client.events)[-500:])
    names = [json.loads(m["text"])["name"] for m in client.of("message")]
    assert names == [f"b{n}" for n in range(sent - HISTORY, sent)]


def test_no_subscription_is_refused_over_many_sessions_of_channels_made_while_connecting(net: Network, official,
                                                                                          figure):
    """About 1 session of 8 lost a channel to 'Unknown channel ID' (the SDK advertised it before
    it could be subscribed to): 30 sessions, each with 10 channels made as it connects."""
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    sessions, per_session = 30, 10
    client = official(server.port, "^pepper/events/", sessions)
    bus = net.bus("robot")
    started = time.monotonic()

    def run(session: int) -> None:
        mark = len(client.events)
        kinds = [f"k{session}x{i}" for i in range(per_session)]
        for kind in kinds:  # (while the client connects, is told of the channels and subscribes)
            bus.put(f"pepper/events/{kind}", event(kind, n=session))
        wait_for(lambda: {m["topic"] for m in client.of("message", mark)} >= {f"pepper/events/{k}" for k in kinds},
                 15, f"session {session}: a message of each of its {per_session} new channels",
                 lambda: str(client.events[mark:])[-2000:])
        assert not client.of("status", mark) and not client.of("error", mark), client.events[mark:]
        client.next_session()
        wait_for(lambda: len(client.of("close", mark)) == 1, 10, "the session closed")

    for session in range(sessions):
        run(session)
    figure("official client sessions, each with 10 channels made while it connected, none refused", sessions)
    figure("time for 30 sessions", time.monotonic() - started, "s")
    assert server.stats["bad"] == 0


def test_a_robot_that_leaves_is_unadvertised_and_when_it_comes_back_the_official_client_follows_it(
        net: Network, official):
    """Robots come and go during a show: the channels of one that leaves are unadvertised (they
    stayed advertised, frozen at their last message, which a client that connected later still got
    as the channel's latest), and advertised anew when it comes back; the client, unsubscribing as
    Lichtblick does on ``unadvertise`` and subscribing again to the new channel, hears no error.
    Message log times are the server's clock, in nanoseconds; serverInfo names no capability."""
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    client = official(server.port, "^pepper/frame$")
    wait_for(lambda: client.of("serverInfo"), 15, "the official client connected", lambda: str(client.events))
    info = client.of("serverInfo")[0]
    assert info["capabilities"] == [] and "supportedEncodings" not in info and "ROS_DISTRO" not in info["metadata"]
    before = time.time_ns()
    robot = net.sim("pepper", rate_hz=20)
    wait_for(lambda: client.of("message"), 15, "pepper/frame's messages", lambda: str(client.events)[-2000:])
    first = client.of("message")[0]
    assert first["topic"] == "pepper/frame" and before <= int(first["logTime"]) <= time.time_ns()
    frame_id = next(a["id"] for a in client.of("advertise") if a["topic"] == "pepper/frame")
    robot.stop()
    wait_for(lambda: client.of("unadvertise"), 10, "pepper's channels unadvertised", lambda: str(client.events)[-2000:])
    advertised = {a["id"] for a in client.of("advertise") if a["topic"].startswith("pepper/")}
    assert set(client.of("unadvertise")[0]["ids"]) == advertised and frame_id in advertised
    assert server.metrics()["channels"] == 0
    mark = len(client.events)
    net.sim("pepper", rate_hz=20)
    wait_for(lambda: client.of("message", mark), 15, "pepper/frame's messages again",
             lambda: str(client.events[mark:])[-2000:])
    again = next(a["id"] for a in client.of("advertise", mark) if a["topic"] == "pepper/frame")
    assert again != frame_id  # (a new channel: a viewer never takes it for the old one's cached schema)
    assert not client.of("status") and not client.of("error"), [e for e in client.events if e["ev"] in ("status",
                                                                                                          "error")]
    assert server.stats["bad"] == 0
