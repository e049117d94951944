"""Console view (adapter ``console``): a line per second per robot, and events."""

from __future__ import annotations

import collections
import sys
import time
from dataclasses import dataclass
from typing import TextIO

from sonibus.bus import keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.presence import watch_robots
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Streams

__all__ = ["ConsoleConfig", "ConsoleView"]

MAX_ROBOTS = 32  # robots shown, a line each per interval (names made up on the bus must not add lines)


@dataclass(frozen=True)
class ConsoleConfig:
    """Options of the ``console`` adapter."""

    robots: str = "*"            # key chunk of the robots to show
    joints: tuple[str, ...] = ("HeadYaw", "HeadPitch", "RShoulderPitch", "RElbowRoll", "LShoulderPitch")
    every_s: float = 1.0
    events: bool = True
    per_joint_keys: bool = False  # joints from <robot>/joints/* instead of <robot>/frame (bus/streams.py)


class ConsoleView(Adapter):
    """Prints each robot's frame rate and a few joint values once a second, and every event."""

    Config = ConsoleConfig
    out: TextIO = sys.stdout

    def _start(self) -> None:
        cfg: ConsoleConfig = self.config
        self._queue = self.own(SampleQueue(8192))
        # Joints and events by name: a broad "*/**" would keep every owner putting its per-joint keys.
        self._streams = self.own(Streams(self.bus, [keys.joints(cfg.robots), keys.event(cfg.robots, "*")],
                                         self._queue, per_joint_keys=cfg.per_joint_keys))
        self._values: dict[str, dict[str, float]] = {}
        self._seqs: dict[str, set[int]] = {}
        self._left: collections.deque[str] = collections.deque()  # robots gone from the bus, from Zenoh's threads
        self.own(watch_robots(self.bus, lambda robot, alive: alive or self._left.append(robot), self.capped))
        self.spawn(self._run, "view")

    def _run(self) -> None:
        next_line = time.monotonic() + self.config.every_s
        while not self.stopping.is_set():
            item = self._queue.get(timeout=max(0.0, next_line - time.monotonic()))
            if item is not None:
                self._take(*item)
            if time.monotonic() >= next_line:
                self._print_rates()
                next_line += self.config.every_s

    def _take(self, key: str, payload: bytes) -> None:
        message = self._streams.take(key, payload, self.count, self.warn)
        if message is None:
            return
        source = message.source
        if source.section in ("joints", "frame"):
            if source.robot not in self._values and len(self._values) >= MAX_ROBOTS:
                self.capped(f"robot '{source.robot}' not shown: already {MAX_ROBOTS} robots, a line each")
                return
            values = self._values.setdefault(source.robot, {})
            for sample in message.joints:
                if sample.source.name in self.config.joints:  # (only those shown: joint names can be made up)
                    values[sample.source.name] = sample.values[0]
            self._seqs.setdefault(source.robot, set()).add(message.seq)
        elif message.event is not None and self.config.events and source.name != "command":
            details = " ".join(f"{k}={v}" for k, v in message.event.items() if k not in ("t", "kind"))
            self._print(f"{source.robot:<8} event {source.name}: {details}")

    def _print_rates(self) -> None:
        while self._left:  # a replay that ended, a robot switched off: no line at 0.0 frames/s for ever
            robot = self._left.popleft()
            if self._values.pop(robot, None) is not None:
                self._print(f"{robot:<8} left the bus")
        for robot, values in sorted(self._values.items()):
            rate = len(self._seqs.get(robot, ())) / self.config.every_s
            shown = "  ".join(f"{j} {values[j]:+.3f}" for j in self.config.joints if j in values)
            self._print(f"{robot:<8} {rate:6.1f} frames/s  {shown}")
        self._seqs = {}

    def _print(self, line: str) -> None:
        print(line, file=self.out, flush=True)
        self.count("sent")
