"""libmapper devices (adapter ``libmapper``, extra ``libmapper``): every robot on the bus
as a libmapper device named after it, for webmapper, libmapper-aware Max and Pd patches
and any program that uses libmapper.

    [nodes.mapper]
    adapter = "libmapper"
    interface = "eth0"

Device ``pepper.<ordinal>`` has an output signal per joint (``joints/HeadYaw``: rad,
its limits as min and max) and derived value (``derived/hand/RHand``), updated from
the robot's frames, and an input signal per joint (``cmd/joints/set/HeadYaw``) whose
values become ``joints/set`` commands, validated by the robot's owner like any other
(``commands.py``). Maps other programs make with these signals are saved to a file and
made again when either end restarts (``keeper.py``). docs/libmapper.md has it all.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from pathlib import Path
from typing import Any

from sonibus.bus.adapter import Adapter
from sonibus.bus.errors import ConfigError
from sonibus.bus.info import InfoRequests
from sonibus.bus.presence import watch_robots
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Streams

from .commands import Commands
from .config import LibmapperConfig
from .devices import MAX_DEVICES, Devices
from .keeper import Keeper
from .saved import MapFile

__all__ = ["Libmapper", "LibmapperConfig"]

log = logging.getLogger(__name__)

SUBSCRIBE = ("*/joints/*", "*/derived/**")
INFO_EVERY_S = 2.0   # how often each robot's info is asked again (a features node adds derived values)
POLL_S = 0.005       # the libmapper thread's longest wait: inputs and maps are handled this soon
TICK_S = 0.1         # how often saved maps are looked after
CHANGES = 1024       # robots coming, going and described, waiting for the libmapper thread


class Libmapper(Adapter):
    """Every robot on the bus as a libmapper device: joints out, joint targets in, maps kept."""

    Config = LibmapperConfig
    counters = ("inputs", "refused_values", "commands", "commands_refused",
                "maps_saved", "maps_not_back", "maps_refused", "robots_left_out")

    def __init__(self, config: LibmapperConfig | None = None, *, name: str = "") -> None:
        super().__init__(config, name=name)
        self._keeper: Keeper | None = None
        self._served = 0

    def _start(self) -> None:
        cfg: LibmapperConfig = self.config
        self._file = MapFile(Path(self.resolve(cfg.maps)))
        try:  # (a file that cannot be read stops the start here, in one line, and is left as it is)
            self._file.load()
        except ValueError as exc:
            raise ConfigError(f"node '{self.name}': key 'maps': {exc}") from None
        names = [name for _, name in socket.if_nameindex()]
        if cfg.interface and cfg.interface not in names:  # (libmapper would pick another one, unsaid)
            raise ConfigError(f"node '{self.name}': key 'interface': no interface '{cfg.interface}' on this "
                              f"machine — interfaces: {', '.join(names)}")
        self._changes: queue.Queue[tuple[str, str, Any]] = queue.Queue(CHANGES)
        self._frames = self.own(SampleQueue(cfg.queue))
        self._info = InfoRequests(self.bus, lambda robot, info: self._change("info", robot, info),
                                  lambda robot, text: self.warn("info", text), INFO_EVERY_S)
        self._present: set[str] = set()  # robots on the bus (written by the claims' worker, read by the others)
        self._present_lock = threading.Lock()
        self._commands = Commands(self.bus, cfg.command_hz, cfg.speed, cfg.timeout, self.count, self.warn)
        self._streams = self.own(Streams(self.bus, SUBSCRIBE, self._frames, pace=False))  # (every frame: no spacing)
        self.spawn(self._run, "libmapper")
        self.own(watch_robots(self.bus, self._robot_changed, self.capped))
        self.spawn(lambda: self._info.keep_asking(self.stopping, self._on_bus), "info")
        self.address = (f"libmapper devices on {cfg.interface or 'the interface libmapper picks'}, "
                        f"maps kept in {self._file.path}")
        log.info("%s: %s", self.name, self.address)

    # -- the bus side -----------------------------------------------------------------

    def _wanted(self, robot: str) -> bool:
        return not self.config.robots or robot in self.config.robots

    def _robot_changed(self, robot: str, alive: bool) -> None:
        if not self._wanted(robot):
            return
        with self._present_lock:
            (self._present.add if alive else self._present.discard)(robot)
        self._change("robot", robot, alive)
        if alive:
            self._info.ask(robot)

    def _change(self, kind: str, robot: str, what: Any) -> None:
        try:
            self._changes.put_nowait((kind, robot, what))
        except queue.Full:
            self.capped(f"{kind} of robot '{robot}' not taken: {CHANGES} changes already wait")

    def _on_bus(self) -> list[str]:
        with self._present_lock:
            return list(self._present)

    # -- the libmapper thread -------------------------------------------------------------

    def _run(self) -> None:
        cfg: LibmapperConfig = self.config
        devices = Devices(cfg.interface, self._commands.take, self._map_changed, self._device_left, cfg.commands)
        try:
            self._keeper = Keeper(self._file, devices, cfg.max_maps, cfg.restore_s,
                                  lambda kind, text: log.warning("%s: %s", self.name, text),
                                  self.count)
            ticked = 0.0
            while not self.stopping.is_set():
                self._take_changes(devices)
                for key, payload in self._frames.drain(timeout=POLL_S):
                    message = self._streams.take(key, payload, self.count, self.warn)
                    if message is not None:
                        self._publish(devices, message)
                devices.poll()
                self._served = len(devices.robots)
                self._commands.flush()
                if time.monotonic() - ticked >= TICK_S:
                    ticked = time.monotonic()
                    self._keeper.tick()
        finally:
            self._keeper = None
            devices.close()

    def _map_changed(self, found: Any, present: bool) -> None:
        if self._keeper is not None and not self.stopping.is_set():  # (our devices leaving is no removal)
            self._keeper.changed(found, present)

    def _device_left(self, device: str) -> None:
        if self._keeper is not None and not self.stopping.is_set():
            self._keeper.left(device)

    def _take_changes(self, devices: Devices) -> None:
        for _ in range(64):  # (a few each round: frames and polls go on)
            try:
                kind, robot, what = self._changes.get_nowait()
            except queue.Empty:
                return
            with self._present_lock:
                present = robot in self._present
            if kind == "robot" and not what:
                self._commands.forget(robot)
                if devices.drop_robot(robot):
                    log.info("%s: robot '%s' left: its device is off the network", self.name, robot)
            elif kind == "info" and present:  # (a robot that left while its info was on the way is not served)
                self._describe(devices, robot, what)

    def _describe(self, devices: Devices, robot: str, info: dict[str, Any]) -> None:
        new = robot not in devices.robots
        if new and len(devices.robots) >= MAX_DEVICES:
            self.capped(f"robot '{robot}' not served: already {MAX_DEVICES} devices")
            return
        try:
            problems = devices.set_robot(robot, info)
        except (KeyError, TypeError, ValueError) as exc:
            self.count("robots_left_out")
            self.warn(f"info:{robot}", f"robot '{robot}' not served: its info is unusable "
                                       f"({type(exc).__name__}: {exc})")
            return
        for problem in problems:
            self.warn(f"info:{robot}", problem)
        if new:
            log.info("%s: robot '%s' is libmapper device '%s'", self.name, robot, robot)

    def _publish(self, devices: Devices, message: Incoming) -> None:
        if message.event is not None:
            return
        robot = message.source.robot
        for sample in message.joints:
            if devices.publish(robot, sample.source.key[len(robot) + 1:], sample.values):
                self.count("sent")  # (values handed to libmapper: it sends those that are mapped)
        self.record_latency(time.time() - message.t)

    def metrics(self) -> dict[str, Any]:
        """Devices served; maps kept in the file, running, and what each that is not back waits for."""
        keeper = self._keeper
        return {"devices": self._served, **keeper.snapshot} if keeper is not None else {}
