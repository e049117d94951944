"""MIDI sink (adapter ``midi``): joint samples → control changes or pitch bend,
behavior and speech events → notes, on a virtual port or an existing one."""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from sonibus.bus import presence
from sonibus.bus.adapter import Adapter
from sonibus.bus.info import InfoRequests
from sonibus.bus.keys import Key
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Selected, Streams, if_free

from . import mapping, ports
from .config import MidiSinkConfig

log = logging.getLogger(__name__)

INFO_RETRY_S = 2.0
HARDWARE_MESSAGES_PER_S = 1000   # 31250 baud / 30 bits per 3-byte message ≈ 1041
MAX_ROBOTS = 64                  # robots played (16 channels): names made up on the bus must not grow the tables
MAX_CONTROLLERS = 4096           # keys mapped (or found unmappable) at most
INFO = "\0info"                  # queue items carrying a robot's info, so only the worker touches state
HEARD_EVERY_S = 0.5              # how often a robot's data is told to presence (its silence is warned of after 3 s)


@dataclass
class _Controller:
    """One MIDI controller (a CC, a 14-bit CC pair, or a channel's pitch bend) fed by one joint."""

    channel: int
    cc: int                 # -1: pitch bend
    resolution: int
    low: float
    high: float
    last: int | None = None
    last_sent: float = -math.inf
    held: int | None = None

    @property
    def top(self) -> int:
        return mapping.MAX7 if self.resolution == 7 else mapping.MAX14

    def messages(self, number: int) -> list[list[int]]:
        if self.cc == -1:
            return mapping.pitch_bend(self.channel, number)
        return mapping.cc_messages(self.channel, self.cc, number, self.resolution)


@dataclass
class _Robot:
    channel: int
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    order: list[str] = field(default_factory=list)
    behaviors: list[str] = field(default_factory=list)
    rate_hz: float = 0.0
    known: bool = False     # info arrived
    notes: dict[int, str] = field(default_factory=dict)  # behavior note → the first behavior heard on it


# a frame's played joints (``MidiSink._played``): index among the selected, controller, low, span, top
Played = tuple[tuple[int, _Controller, float, float, int], ...]


class MidiSink(Adapter):
    """Robots as MIDI: joints on controllers, behaviors and speech as notes (for a DAW or a synth)."""

    Config = MidiSinkConfig
    counters = ("notes", "held", "waiting_info", "unmapped", "send_errors", "skipped")

    def _start(self) -> None:
        cfg: MidiSinkConfig = self.config
        self.estimated_rate = 0.0   # 3-byte messages/s the mapping may produce at the robots' rates
        self._robots: dict[str, _Robot] = {}
        self._controllers: dict[str, _Controller | None] = {}
        self._held: set[str] = set()
        self._sounding: set[tuple[int, int]] = set()
        self._interval = 1.0 / cfg.max_rate_hz if cfg.max_rate_hz else 0.0
        self._heard: dict[str, float] = {}  # robot → when its data was last told to presence
        self._frames: dict[str, tuple[Selected, Played]] = {}  # robot → _played's last
        self._out = ports.open_output(cfg.api, cfg.port, cfg.connect, client=self.name)
        self.own(ports.Closer(self._out))
        self._queue = self.own(SampleQueue(cfg.queue))
        self._tally = self.stats.tally(("received", "sent"))  # (counted under self._state: no lock of their own)
        self._counted = self.stats.counting(self._tally)
        self._info = InfoRequests(self.bus, lambda robot, info: self._queue.put((INFO, (robot, info))),
                                  lambda robot, text: self.warn("info", text), INFO_RETRY_S,
                                  derived_alone=True)
        self._presence = self.own(presence.connection_events(self.bus, self._queue, cfg.subscribe,
                                                             self.capped))  # loss, return
        # Frames are taken where they arrive (a thread hand-off less, as the OSC sink's) unless held
        # controllers (max_rate_hz) need the worker's timing; one lock between them guards the state.
        self._state = threading.Lock()
        self._streams: Streams | None = None  # (a frame may arrive while Streams subscribes: queued, see _direct)
        self._streams = self.own(Streams(self.bus, cfg.subscribe, self._queue, per_joint_keys=cfg.per_joint_keys,
                                         direct=None if cfg.max_rate_hz else self._direct))
        self.when_stopping(self._queue.close)      # (its worker waits on it, not on stopping)
        self.when_stopping(self._presence.wake)
        self.spawn(lambda: self._presence.watch(self.stopping), "silence")
        self.spawn(self._forward, "forward")
        self.address = f"MIDI out on {f'{cfg.connect!r}' if cfg.connect else f'virtual port {cfg.port!r}'}"
        log.info("%s: %s", self.name, self.address)

    @property
    def channels(self) -> dict[str, int]:
        """Robot → the channel it plays on."""
        return {robot: r.channel for robot, r in self._robots.items()}

    # -- the loop ---------------------------------------------------------------------

    def _forward(self) -> None:
        try:
            while not self.stopping.is_set():
                item = self._queue.get(timeout=self._wait())
                with self._state:
                    now = time.monotonic()  # (once the lock is had: a frame taken where it arrived may have held it)
                    if item is not None:
                        self._take(*item, now)
                    self._tick(now)
        finally:
            with self._state:
                self._notes_off()

    def _direct(self, key: str, payload: Any) -> bool:
        """A frame, on its subscription's callback thread (``Streams``' ``direct``); into the
        queue instead (False) before it subscribed everywhere or while the worker holds the
        state (``if_free``)."""
        return self._streams is not None and if_free(self._state, lambda: self._take(key, payload, time.monotonic()))

    def _wait(self) -> float | None:
        """Until a held controller's turn (``max_rate_hz``); with none held, until a message comes
        or the stop closes the queue (None). Only the worker holds controllers: with
        ``max_rate_hz`` every frame comes through the queue."""
        if not self._held:
            return None
        soonest = min(self._controllers[k].last_sent for k in self._held) + self._interval  # type: ignore[union-attr]
        return max(0.0, soonest - time.monotonic())

    def _tick(self, now: float) -> None:
        for key in list(self._held):
            controller = self._controllers[key]
            assert controller is not None
            if now - controller.last_sent >= self._interval:
                self._held.discard(key)
                number, controller.held = controller.held, None
                if number is not None and number != controller.last:
                    self._emit(controller, number, now)

    def _take(self, key: str, payload: Any, now: float) -> None:
        if key == INFO:
            self._learn(*payload)
            return
        message = self._streams.take(key, payload, self._counted, self.warn)  # type: ignore[union-attr]
        if message is None:
            return
        source = message.source
        if source.robot not in self._robots and len(self._robots) >= MAX_ROBOTS:
            self.capped(f"robot '{source.robot}' not played: already {MAX_ROBOTS} robots (16 channels)")
            return
        if source.section in ("frame", "joints") and now - self._heard.get(source.robot, -math.inf) >= HEARD_EVERY_S:
            if len(self._heard) >= 4096:  # (robot names come from the network)
                self._heard.clear()
            self._heard[source.robot] = now
            self._presence.heard_from(source.robot)
        if message.event is not None:
            if self._presence.passes(source.robot, message.event):
                self._event(source, message.event)
            return
        if message.selected is not None:  # a frame: its selected joints, without a sample made of each
            played = None if self._interval else self._played(source.robot, message.selected)
            if played is not None:
                self._frame(played, message.values, now)
            else:
                for joint, value in zip(message.selected.sources, message.values, strict=True):
                    self._sample(joint, value, now)
        else:
            for sample in message.joints:
                self._sample(sample.source, sample.values[0], now)
        self.record_latency(time.time() - message.t)

    def _sample(self, source: Key, value: float, now: float) -> None:
        if source.section not in ("joints", "derived"):
            return
        robot = self._robot(source.robot)
        if not robot.known:
            self.count("waiting_info")
            self._info.ask(source.robot)
            return
        controller = self._controller(source, robot)
        if controller is None:
            return
        number = mapping.scale(value, controller.low, controller.high, controller.top)
        if now - controller.last_sent < self._interval:
            controller.held = number     # the newest waits for its turn
            self._held.add(source.key)
            self.count("held")
        elif number != controller.last:
            self._emit(controller, number, now)

    def _played(self, robot: str, selected: Selected) -> Played | None:
        """The controllers of the joints ``selected`` of ``robot``'s frames, each with the joint's
        index among them and its scaling (``mapping.span``), worked out once per selection
        (``Selected`` is kept by ``Streams``: found by identity) and kept as the robot's last;
        None while its info has not come."""
        last = self._frames.get(robot)
        if last is not None and last[0] is selected:
            return last[1]
        shown = self._robots.get(robot)
        if shown is None or not shown.known:
            return None
        controllers = [self._controller(joint, shown) for joint in selected.sources]
        played = tuple((i, c, c.low, mapping.span(c.low, c.high), c.top) for i, c in enumerate(controllers)
                       if c is not None)
        if all(joint.key in self._controllers for joint in selected.sources):  # (past MAX_CONTROLLERS: per frame)
            self._frames[robot] = (selected, played)  # (robots are capped: MAX_ROBOTS)
        return played

    def _frame(self, played: Played, values: tuple[float, ...], now: float) -> None:
        """A frame's values on their controllers (``_played``), each sent if its number changed:
        ``_sample``'s work without ``max_rate_hz`` (nothing held), with ``mapping.scale`` inlined
        (three calls a joint less: it was most of a frame's own work; issue 35)."""
        for i, controller, low, span, top in played:
            number = round(min(1.0, max(0.0, (values[i] - low) / span)) * top)  # (mapping.span says why: scale)
            if number != controller.last:
                self._emit(controller, number, now)

    def _emit(self, controller: _Controller, number: int, now: float) -> None:
        controller.last, controller.last_sent = number, now
        for message in controller.messages(number):
            self._send(message)

    def _send(self, message: list[int]) -> None:
        try:
            self._out.send_message(message)
            self._tally["sent"] += 1
        except Exception as exc:  # rtmidi raises its own errors for a port gone away
            self.count("send_errors")
            self.warn("send", f"cannot send MIDI: {exc}")

    # -- mapping ----------------------------------------------------------------------

    def _robot(self, name: str) -> _Robot:
        robot = self._robots.get(name)
        if robot is None:
            robot = self._robots[name] = _Robot(self._channel_for(name))
        return robot

    def _channel_for(self, name: str) -> int:
        fixed = self.config.channels or {}
        if name in fixed:
            return fixed[name]
        taken = set(fixed.values()) | {r.channel for r in self._robots.values()}
        free = [c for c in range(1, 17) if c not in taken]
        if not free:
            self.warn("channels", f"more than 16 robots: '{name}' shares channel 16 (set channels = {{...}})")
            return 16
        return free[0]

    def _controller(self, source: Key, robot: _Robot) -> _Controller | None:
        if source.key in self._controllers:
            return self._controllers[source.key]
        if len(self._controllers) >= MAX_CONTROLLERS:
            self.capped(f"key '{source.key}' not played: already {MAX_CONTROLLERS} keys mapped or not")
            return None
        cfg: MidiSinkConfig = self.config
        entry = cfg.entries.get(source.key)
        controller = None
        joint = source.section == "joints"
        span = robot.ranges.get(source.name if joint else f"{source.feature}/{source.name}")
        if span is None:
            if entry is not None and not joint:  # its processor may have started after the info came: ask again
                self.warn("unknown", f"map key '{source.key}': no range for it in {source.robot}/info/derived "
                                      f"yet (is a features node running?)")
                self._info.ask(source.robot)
                return None
            if entry is not None:
                self.warn("unknown", f"map key '{source.key}': {source.robot} has no joint '{source.name}' "
                                      f"— known joints: {', '.join(robot.order)}")
        elif entry is not None:
            controller = _Controller(entry.channel or robot.channel, -1 if entry.pitchbend else entry.cc,
                                     14 if entry.pitchbend else entry.resolution, *span)
        elif cfg.auto_map and joint:  # derived values only by an explicit map entry
            cc = mapping.FIRST_CC + robot.order.index(source.name)
            if cc <= 119:
                controller = _Controller(robot.channel, cc, 7, *span)
        if controller is None:
            self.count("unmapped")
        self._controllers[source.key] = controller
        return controller

    def _learn(self, name: str, info: dict[str, Any]) -> None:
        if name not in self._robots:  # (asked only of robots it took data of: it left meanwhile, or was capped)
            return
        robot = self._robot(name)
        try:
            robot.ranges = {j["name"]: (float(j["min"]), float(j["max"])) for j in info.get("joints", [])}
            robot.ranges.update({d["name"]: (float(d["min"]), float(d["max"])) for d in info.get("derived", [])
                                 if "min" in d and "max" in d})
            robot.order = [j["name"] for j in info.get("joints", [])]
            robot.behaviors = [str(b) for b in info.get("behaviors", [])]
            robot.rate_hz = float(info.get("rate_hz") or 0.0)
        except (KeyError, TypeError, ValueError) as exc:
            self.warn("info", f"{name}/info unusable: {exc}")
            return
        robot.known = True
        self._estimate()
        if self.config.notes and self.config.behavior_note == -1:
            for behavior in robot.behaviors:  # a shared note is said at once, not at the show
                self._behavior_note(name, robot, behavior)

    def _estimate(self) -> None:
        cfg: MidiSinkConfig = self.config
        total = 0.0
        for name, robot in self._robots.items():
            if not robot.known:
                continue
            rate = min(robot.rate_hz, cfg.max_rate_hz) if cfg.max_rate_hz else robot.rate_hz
            explicit = [e for e in cfg.entries.values() if e.key.split("/")[0] == name]
            named = {e.key.split("/", 2)[2] for e in explicit}
            auto = len([j for j in robot.order[:120 - mapping.FIRST_CC] if j not in named]) if cfg.auto_map else 0
            messages = auto + sum(2 if e.resolution == 14 and not e.pitchbend else 1 for e in explicit)
            total += messages * rate
        self.estimated_rate = total
        if cfg.connect and total > HARDWARE_MESSAGES_PER_S:
            log.warning("%s: the mapping may send about %.0f MIDI messages/s to '%s', more than a hardware "
                        "MIDI cable carries (~%d/s) — set max_rate_hz, map fewer joints (auto_map = false) "
                        "or subscribe to fewer keys", self.name, total, cfg.connect, HARDWARE_MESSAGES_PER_S)

    # -- events -----------------------------------------------------------------------

    def _event(self, source: Key, message: dict[str, Any]) -> None:
        cfg: MidiSinkConfig = self.config
        kind, state = str(message.get("kind") or source.name), str(message.get("state", ""))
        robot = self._robot(source.robot)
        if kind == "connection" and state != "connected":  # lost, not answering...: no note may hang
            self._notes_off()
            return
        if not cfg.notes or kind not in ("behavior", "speech"):
            return
        if state not in ("started", "stopped", "done"):
            return
        number = (cfg.speech_note if kind == "speech"
                  else self._behavior_note(source.robot, robot, str(message.get("name", ""))))
        on = state == "started"
        slot = (robot.channel, number)
        if on:
            self._sounding.add(slot)
        elif slot in self._sounding:
            self._sounding.discard(slot)
        else:
            return  # no note off without its note on
        self.count("notes")
        self._send(mapping.note(robot.channel, number, on, cfg.velocity))

    def _behavior_note(self, robot_name: str, robot: _Robot, behavior: str) -> int:
        """The fixed note, the table's, or the name's hash (``mapping.behavior_note``);
        a note two behaviors of a robot share is warned about, naming both."""
        cfg: MidiSinkConfig = self.config
        if cfg.behavior_note != -1:
            return int(cfg.behavior_note)
        table = cfg.behavior_notes or {}
        number = table[behavior] if behavior in table else mapping.behavior_note(behavior, *cfg.behavior_note_range)
        first = robot.notes.setdefault(number, behavior)
        if first != behavior:
            self.warn(f"shared {robot_name} {number}", f"{robot_name}: behaviors '{first}' and '{behavior}' share "
                                                        f"note {number} — give one a note of its own: "
                                                        f"behavior_notes = {{\"{behavior}\" = N}}")
        return number

    def _notes_off(self) -> None:
        """All notes off (CC 123) on every channel used."""
        used = {r.channel for r in self._robots.values()} | {c.channel for c in self._controllers.values() if c}
        for channel in sorted(used):
            self._send(mapping.all_notes_off(channel))
        self._sounding.clear()

    # -- info and warnings ------------------------------------------------------------


