"""Console view (adapter ``console``): a line per second per robot, and events."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import TextIO

from sonibus.bus import codec
from sonibus.bus.adapter import Adapter
from sonibus.bus.keys import Key

__all__ = ["ConsoleConfig", "ConsoleView"]


@dataclass(frozen=True)
class ConsoleConfig:
    """Options of the ``console`` adapter."""

    robots: str = "*"            # key chunk of the robots to show
    joints: tuple[str, ...] = ("HeadYaw", "HeadPitch", "RShoulderPitch", "RElbowRoll", "LShoulderPitch")
    every_s: float = 1.0
    events: bool = True


class ConsoleView(Adapter):
    """Prints each robot's frame rate and a few joint values once a second, and every event."""

    Config = ConsoleConfig
    out: TextIO = sys.stdout

    def _start(self) -> None:
        cfg: ConsoleConfig = self.config
        subscriber, self._queue = self.bus.subscribe(f"{cfg.robots}/**", 8192)
        self.own(subscriber)
        self.own(self._queue)
        self._values: dict[str, dict[str, float]] = {}
        self._frames: dict[str, set[int]] = {}
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
        try:
            parsed, message = Key.parse(key), codec.decode(payload)
        except ValueError:
            return
        if parsed.section == "joints":
            self._values.setdefault(parsed.robot, {})[parsed.name] = message.get("v", float("nan"))
            self._frames.setdefault(parsed.robot, set()).add(message.get("seq", -1))
        elif parsed.section == "events" and self.config.events and parsed.name != "command":
            details = " ".join(f"{k}={v}" for k, v in message.items() if k not in ("t", "kind"))
            self._print(f"{parsed.robot:<8} event {parsed.name}: {details}")

    def _print_rates(self) -> None:
        for robot, values in sorted(self._values.items()):
            rate = len(self._frames.get(robot, ())) / self.config.every_s
            shown = "  ".join(f"{j} {values[j]:+.3f}" for j in self.config.joints if j in values)
            self._print(f"{robot:<8} {rate:6.1f} frames/s  {shown}")
        self._frames = {}

    def _print(self, line: str) -> None:
        print(line, file=self.out, flush=True)
