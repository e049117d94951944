"""MIDI controller (adapter ``midi-in``): faders, keys and program changes from a
MIDI input become robot commands, always through ``sonibus.bus.client.ask`` (so the
robot validates them); a key mapped to a scenario asks the robot's show for it
(``client.ask_program``). Fader moves are coalesced to ``rate_hz`` per robot, sending
the newest value of every fader moved since the last command.

On JACK the input is a JACK-Client port (``jack_in.py``: no python-rtmidi, whose
JACK input crashed the process), which says when a controller connects or leaves
and connects again to a new one; ALSA, CoreMIDI and WinMM go through python-rtmidi."""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

from sonibus.bus.adapter import Adapter
from sonibus.bus.client import Outcome, ask, ask_program
from sonibus.bus.errors import CommandError
from sonibus.bus.info import InfoRequests
from sonibus.bus.queue import SampleQueue

from . import mapping, ports
from .config import CcMapping, MidiControllerConfig

log = logging.getLogger(__name__)

INFO_RETRY_S = 2.0
SETTLE_S = 0.5  # a JACK port's change looked at again this long after it was told
SETTLE_WINDOW_S = 5.0  # a change told but not shown yet is looked for every SETTLE_S this long at most
INFO = "\0info"


class MidiController(Adapter):
    """A MIDI controller or a DAW drives robots: CC → joints, notes → behaviors, programs → postures.

    A note may start a scenario of the robot's show instead of a behavior.

    A panic note or CC sends stop."""

    Config = MidiControllerConfig
    counters = ("commands", "ok", "unmapped", "waiting_info", "dropped", "controllers_left")

    def _start(self) -> None:
        cfg: MidiControllerConfig = self.config
        self._lock = threading.Lock()          # the error log is touched by reply callbacks
        self._failed: set[str] = set()         # mappings whose error was logged once
        self._limits: dict[str, dict[str, tuple[float, float]]] = {}
        self._held: dict[tuple[str, str], tuple[int, CcMapping]] = {}   # (robot, joint) → newest value
        self._last_sent: dict[str, float] = {}
        self._interval = 1.0 / cfg.rate_hz
        self._queue = self.own(SampleQueue(cfg.queue))
        self._info = InfoRequests(self.bus, lambda robot, info: self._queue.put((INFO, (robot, info))),
                                  lambda robot, text: self._fail(f"info {robot}", text), INFO_RETRY_S)
        if cfg.api == "jack":
            from .jack_in import JackMidiIn  # (JACK-Client and libjack only for JACK)
            self._jack = self.own(JackMidiIn(self.name, cfg.port, cfg.connect,
                                             lambda message: self._queue.put(("midi", message))))
            self.when_stopping(self._jack.changed.set)  # (its watch waits for a change, or this)
            self.spawn(self._watch, "jack")
        else:
            self.own(ports.Closer(ports.open_input(cfg.api, cfg.port, cfg.connect, self._receive, client=self.name)))
        for robot in {m.robot for m in cfg.mappings("cc")}:
            self._info.ask(robot)
        self.when_stopping(self._queue.close)  # (its worker waits on it, not on stopping)
        self.spawn(self._work, "commands")
        self.address = f"MIDI in on {f'{cfg.connect!r}' if cfg.connect else f'virtual port {cfg.port!r}'}"
        log.info("%s: %s", self.name, self.address)

    def _receive(self, event: tuple[list[int], float], data: Any = None) -> None:
        self._queue.put(("midi", event[0]))   # rtmidi's thread: only enqueue

    def _watch(self) -> None:
        """Says who connects to the JACK port and who leaves; the JACK server gone fails the node."""
        again: float | None = None
        window_end = 0.0  # (monotonic) a connection told and not shown yet is looked for until then
        while not self.stopping.is_set():
            # (JACK tells of a change before its list of connections shows it: after one, a look
            # again SETTLE_S later, and every SETTLE_S while a connection or disconnection of our
            # port that JACK told has not shown, SETTLE_WINDOW_S at most: one look missed a killed
            # controller's leaving on a loaded machine, and nothing told again; with nothing
            # changing, asleep until JACK or the stop wakes it)
            told = self._jack.changed.wait(again)
            came, left = self._jack.changes()
            now = time.monotonic()
            if not self._jack.unshown:
                window_end = 0.0
            elif not window_end:
                window_end = now + SETTLE_WINDOW_S
            elif now >= window_end:
                log.warning("%s: JACK told of a change to %s's connections with %s that never showed in %g s",
                            self.name, self._jack.name, self._jack.forget_told(), SETTLE_WINDOW_S)
                window_end = 0.0
            again = SETTLE_S if told or came or left or window_end else None
            for port in sorted(came):
                log.info("%s: controller '%s' connected to %s", self.name, port, self._jack.name)
            for port in sorted(left):
                self.count("controllers_left")
                counters = ", ".join(f"{k} {v}" for k, v in self.stats.items() if v)
                log.warning("%s: controller '%s' left %s%s (%s)", self.name, port, self._jack.name,
                            f", waiting for a port matching '{self.config.connect}'" if self.config.connect else "",
                            counters)

    # -- the loop ---------------------------------------------------------------------

    def _work(self) -> None:
        while not self.stopping.is_set():
            item = self._queue.get(timeout=self._wait())
            if item is not None:
                kind, payload = item
                if kind == INFO:
                    self._learn(*payload)
                else:
                    self._midi(payload)
            self._flush(time.monotonic())

    def _wait(self) -> float | None:
        """Until a held fader's robot may be sent to (``rate_hz``), or its info asked again
        (``INFO_RETRY_S``: a robot whose limits are not known yet is not sent to); with none
        held, until a message comes or the stop closes the queue (None)."""
        if not self._held:
            return None
        now = time.monotonic()
        soonest = min(self._last_sent.get(robot, -math.inf) + self._interval if robot in self._limits
                      else now + INFO_RETRY_S for robot, _ in self._held)
        return max(0.0, soonest - now)

    def _midi(self, message: list[int]) -> None:
        self.count("received")
        if len(message) < 2:
            return
        kind, channel = message[0] & 0xF0, (message[0] & 0x0F) + 1
        data2 = message[2] if len(message) > 2 else 0
        cfg: MidiControllerConfig = self.config
        if kind == 0xB0:
            handled = self._stop_robots(channel, cc=message[1])
            for m in cfg.mappings("cc"):
                if m.channel == channel and m.cc == message[1]:
                    self._held[(m.robot, m.joint)] = (data2, m)
                    handled = True
        elif kind in (0x90, 0x80):
            on = kind == 0x90 and data2 > 0
            handled = on and self._stop_robots(channel, note=message[1])
            for m in cfg.mappings("notes"):
                if m.channel == channel and m.note == message[1]:
                    if on and m.scenario:
                        self._command(f"note {m.note}", m.robot, "scenario", {"name": m.scenario, "by": "midi"},
                                      ask_program)
                    elif on:
                        self._command(f"note {m.note}", m.robot, "behavior/run", {"name": m.behavior})
                    elif m.stop_on_release:
                        self._command(f"note {m.note}", m.robot, "behavior/stop", {"name": m.behavior})
                    handled = True
        elif kind == 0xC0:
            handled = False
            for m in cfg.mappings("program"):
                if m.channel == channel and message[1] < len(m.postures):
                    self._command(f"program {message[1]}", m.robot, "posture",
                                  {"name": m.postures[message[1]], "speed": m.speed})
                    handled = True
        else:
            handled = False
        if not handled:
            self.count("unmapped")

    def _stop_robots(self, channel: int, note: int = -1, cc: int = -1) -> bool:
        hit = False
        for m in self.config.mappings("stop"):
            if m.channel == channel and ((note != -1 and m.note == note) or (cc != -1 and m.cc == cc)):
                self._command("stop", m.robot, "stop", {})
                hit = True
        return hit

    def _flush(self, now: float) -> None:
        """One joints/set per robot and speed, with the newest value of each fader, at most ``rate_hz``."""
        groups: dict[tuple[str, float], dict[str, float]] = {}
        for (robot, joint), (value, m) in list(self._held.items()):
            if now - self._last_sent.get(robot, -math.inf) < self._interval:
                continue
            limits = self._limits.get(robot)
            if limits is None:
                self.count("waiting_info")
                self._info.ask(robot)
                continue
            del self._held[(robot, joint)]
            if joint not in limits:
                self._fail(f"cc {m.cc}", f"key 'cc': {robot} has no joint '{joint}' — known joints: "
                                         f"{', '.join(limits)}")
                continue
            groups.setdefault((robot, m.speed), {})[joint] = mapping.unscale(value, mapping.MAX7, *limits[joint])
        for (robot, speed), angles in groups.items():
            self._last_sent[robot] = now
            self._command(f"cc {robot}", robot, "joints/set",
                          {"names": list(angles), "angles": list(angles.values()), "speed": speed})

    # -- commands and info ------------------------------------------------------------

    def _command(self, what: str, robot: str, verb: str, args: dict[str, Any],
                 send: Callable[..., None] = ask) -> None:
        """``verb`` to ``robot`` (``send``: ``ask_program`` for its show's scenarios)."""
        self.count("commands")

        def done(outcome: Outcome) -> None:
            if isinstance(outcome, CommandError):
                self._fail(what, f"{robot} {verb}: {outcome}")
            else:
                self.count("ok")

        send(self.bus, robot, verb, args, done, self.config.timeout)

    def _fail(self, what: str, message: str) -> None:
        with self._lock:
            first = what not in self._failed
            self._failed.add(what)
        if first:
            log.error("%s: %s (%s; further errors of this mapping are counted, not logged)",
                      self.name, message, what)
        self.count("errors")  # (after the line: whoever sees the count finds the line said)

    def _learn(self, robot: str, info: dict[str, Any]) -> None:
        try:
            self._limits[robot] = {j["name"]: (float(j["min"]), float(j["max"])) for j in info.get("joints", [])}
        except (KeyError, TypeError, ValueError) as exc:
            self._fail(f"info {robot}", f"{robot}/info unusable: {exc}")
            return
        for m in self.config.mappings("cc"):
            if m.robot == robot and m.joint not in self._limits[robot]:
                self._fail(f"cc {m.cc}", f"key 'cc': {robot} has no joint '{m.joint}' — known joints: "
                                         f"{', '.join(self._limits[robot])}")


