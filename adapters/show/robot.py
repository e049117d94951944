"""The robot as a show sees it, over the bus only: the commands anyone could send
(``bus/client.py``), the events its owner publishes, and whether it is there.

It is there ("available") while its owner's token is on the bus, its owner answers
``<robot>/info``, and neither the info nor the owner's latest ``connection`` event
says it is not connected. A robot is lost as soon as one of those fails: its token
goes (a process killed or cut off, within the transport lease), a ``connection``
event says anything but ``connected`` (``lost``, and any state an owner adds later:
``connecting``, ``not answering``...; ``standby`` speaks of another owner and is
left alone), or a command gets no answer or an answer that says the robot is not
there. It is back only once its info says so again (asked every ``PROBE_S``).

Everything arrives in one bounded queue, read by the show's one worker: events
(checked by the gate, as any sink's), and markers for presence and info.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from sonibus.bus import client, keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.claimwatch import owners
from sonibus.bus.errors import CommandError
from sonibus.bus.info import InfoRequests
from sonibus.bus.presence import watch_robots
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Streams

log = logging.getLogger(__name__)

PROBE_S = 1.0  # a robot that is not there is asked for its info this often
QUEUE = 4096   # events waiting for the worker (an operator's sliders send 20 command events a second)
PRESENCE, INFO, WAKE = "\0presence", "\0info", "\0wake"  # markers beside the events in the queue
# A refusal that means the robot is not there (not that the command was wrong): nobody owns it, nobody
# answered, or its owner says it is not connected (today a "failed" saying so; a typed code later)
LOST_CODES = ("robot_not_found", "timeout", "not_connected", "not_answering", "unavailable", "disconnected")
NOT_THERE = ("is not connected", "not connected yet")


class Lost(Exception):
    """The robot went away (why, in one line)."""


class Stopping(Exception):
    """The show's node stops: whatever waits gives up."""


def connection_state(info: dict[str, Any]) -> str | None:
    """What an owner's info says of its link to the robot: a ``connection`` state (a
    string, or a map with ``state``), or an adapter's own ``connected`` flag (the naoqi
    adapter's ``{"naoqi": {"connected": false}}``); None when it says nothing (a simulator)."""
    said = info.get("connection")
    if isinstance(said, str):
        return said
    if isinstance(said, dict) and isinstance(said.get("state"), str):
        return said["state"]
    for value in info.values():
        if isinstance(value, dict) and isinstance(value.get("connected"), bool):
            return "connected" if value["connected"] else "lost"
    return None


class Robot:
    """``robot``'s commands, events and presence for ``adapter`` (a started node)."""

    def __init__(self, adapter: Adapter, robot: str, command_timeout_s: float) -> None:
        self.adapter, self.name, self.timeout = adapter, robot, command_timeout_s
        bus = adapter.bus
        self.queue = adapter.own(SampleQueue(QUEUE))
        self.present = False           # its owner's token is on the bus
        self.available = False         # ... and it is connected, as far as the show knows
        self.why = "not seen yet"      # why it is not available
        self.info: dict[str, Any] = {}
        owners(bus)  # (the view of owners every command names, kept from now: the first command too)
        self._info = InfoRequests(bus, lambda robot, info: self.queue.put((INFO, info)),
                                  lambda robot, text: adapter.warn("info", text), PROBE_S)
        self.streams = adapter.own(Streams(bus, [keys.event(robot, "*")], self.queue))
        adapter.own(watch_robots(bus, self._presence))

    def _presence(self, robot: str, alive: bool) -> None:  # (a Zenoh thread: only enqueue)
        if robot == self.name:
            self.queue.put((PRESENCE, alive))

    def wake(self) -> None:
        """Wake the worker waiting on the queue (a request came)."""
        self.queue.put((WAKE, None))

    # -- what comes in ---------------------------------------------------------------------

    def next(self, timeout: float) -> Incoming | None:
        """The next event of the robot (checked), within ``timeout``; None for a marker or
        nothing. Markers update ``available`` on the way."""
        item = self.queue.get(timeout=max(0.0, timeout))
        if item is None:
            return None
        key, payload = item
        if key == PRESENCE:
            self.present = payload
            if payload:
                self.probe()
            else:
                self.lose("its owner left the bus")
            return None
        if key == INFO:
            self._take_info(payload)
            return None
        if key == WAKE:
            return None
        event = self.streams.take(key, payload, self.adapter.count, self.adapter.warn)
        if event is not None and event.source.name == "connection":
            state = str(event.event.get("state", "")) if event.event else ""
            if state == "connected":
                self.probe()
            elif state != "standby":
                self.lose(f"its owner says '{state}'" + (f" ({event.event['error']})"
                                                         if event.event and event.event.get("error") else ""))
        return event

    def probe(self) -> None:
        """Ask for the robot's info (``InfoRequests`` sends at most one query a ``PROBE_S``):
        its answer decides whether the robot is there."""
        self._info.ask(self.name)

    def _take_info(self, info: dict[str, Any]) -> None:
        self.info = info
        state = connection_state(info)
        if not self.present:
            return
        if state in (None, "connected"):
            if not self.available:
                log.info("%s: robot '%s' is there (%s)", self.adapter.name, self.name,
                         f"owner {info.get('owner', {}).get('node', '?')}")
            self.available, self.why = True, ""
        else:
            self.lose(f"its owner says '{state}'")

    def lose(self, why: str) -> None:
        if self.available:
            log.warning("%s: robot '%s' lost: %s", self.adapter.name, self.name, why)
        self.available, self.why = False, why

    # -- commands ----------------------------------------------------------------------------

    def command(self, verb: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        """Send a command as anyone would, and wait for the answer; ``Lost`` if the robot is
        not there (the answer says so, or none came), ``CommandError`` if it refused."""
        self.adapter.count("commands")
        answered = threading.Event()
        outcomes: list[client.Outcome] = []

        def done(outcome: client.Outcome) -> None:
            outcomes.append(outcome)
            answered.set()

        client.ask(self.adapter.bus, self.name, verb, args or {}, done, self.timeout)
        deadline = time.monotonic() + self.timeout + 1.0  # (ask answers by its timeout: this is a backstop)
        while not answered.wait(0.1):
            if self.adapter.stopping.is_set():
                raise Stopping(f"{verb}: the show stops")
            if time.monotonic() > deadline:
                outcomes.append(CommandError("timeout", f"robot '{self.name}' did not answer '{verb}'"))
                break
        outcome = outcomes[0]
        if not isinstance(outcome, CommandError):
            return outcome
        self.adapter.count("refused_commands")
        if outcome.code in LOST_CODES or any(words in outcome.message for words in NOT_THERE):
            self.lose(f"{verb}: {outcome.message}")
            raise Lost(f"{verb}: {outcome.message}")
        raise outcome

    def behaviors(self) -> list[str] | None:
        """The behaviors its info lists (None before any info)."""
        listed = self.info.get("behaviors")
        return list(listed) if isinstance(listed, list) else None


def matching(kind: str, **fields: Any) -> Callable[[Incoming], bool]:
    """A test of an event: of ``kind``, with ``fields`` (a tuple: any of its values)."""
    def test(event: Incoming) -> bool:
        if event.source.name != kind or event.event is None:
            return False
        return all(event.event.get(k) in (v if isinstance(v, tuple) else (v,)) for k, v in fields.items())
    return test
