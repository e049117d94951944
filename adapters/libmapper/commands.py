"""Joint targets that libmapper peers send into input signals, as ``joints/set`` commands.

libmapper clamps nothing and sends as often as its source changes (a map from a
100 Hz signal, a fader dragged fast). So: a value that is not a finite number is
refused here and counted (nothing is sent); the latest target of each joint waits,
and at most ``hz`` commands a second go to one robot, one at a time, each carrying
every joint that changed since the last. The robot's owner validates them like any
other command: a target past a joint's limits is refused there (``out_of_range``,
nothing moves), and the refusal is said in this node's log and counted.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

from sonibus.bus.client import Outcome, ask
from sonibus.bus.errors import CommandError
from sonibus.bus.node import Bus


class Commands:
    """Targets in (``take``, on the libmapper thread), commands out (``flush``, on the same thread)."""

    def __init__(self, bus: Bus, hz: float, speed: float, timeout: float,
                 count: Callable[[str], None], warn: Callable[[str, str], None]) -> None:
        self.bus, self.every, self.speed, self.timeout = bus, 1.0 / hz, speed, timeout
        self.count, self.warn = count, warn
        self.targets: dict[str, dict[str, float]] = {}  # robot → joint → latest target (robots and joints: served)
        self._sent: dict[str, float] = {}               # robot → when its last command left (monotonic)
        self._waiting: set[str] = set()                 # robots whose last command is not answered yet
        self._lock = threading.Lock()                   # (answers come on Zenoh's threads)

    def take(self, robot: str, joint: str, value: Any) -> None:
        """A value a peer sent into ``robot``'s ``cmd/joints/set/<joint>``."""
        if value is None:  # (an instance released: no value, nothing to do)
            return
        if isinstance(value, list | tuple) and len(value) == 1:
            value = value[0]
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            self.count("refused_values")
            self.warn("refused_values", f"{robot} {joint}: {str(value)[:40]} from libmapper is not a finite "
                                        f"number — refused, nothing sent to the robot (check the map's expression)")
            return
        self.count("inputs")
        self.targets.setdefault(robot, {})[joint] = float(value)

    @property
    def idle(self) -> bool:
        """Whether no target waits and no command is unanswered."""
        with self._lock:
            return not self._waiting and not any(self.targets.values())

    def forget(self, robot: str) -> None:
        """``robot`` is no longer served."""
        self.targets.pop(robot, None)
        self._sent.pop(robot, None)

    def flush(self) -> None:
        """Send each robot its waiting targets, if its rate allows and its last command was answered."""
        now = time.monotonic()
        for robot, joints in self.targets.items():
            if not joints or now - self._sent.get(robot, -math.inf) < self.every:
                continue
            with self._lock:
                if robot in self._waiting:
                    continue
                self._waiting.add(robot)
            self._sent[robot] = now
            names, angles = list(joints), list(joints.values())
            joints.clear()
            self._send(robot, names, angles)

    def _send(self, robot: str, names: list[str], angles: list[float]) -> None:
        def done(outcome: Outcome) -> None:
            with self._lock:
                self._waiting.discard(robot)
            if isinstance(outcome, CommandError):
                self.count("commands_refused")
                asked = ", ".join(f"{n} = {a:g}" for n, a in zip(names, angles, strict=True))
                self.warn(f"refused:{robot}", f"{robot} refused joints/set ({asked}) from libmapper: "
                                              f"{outcome.code}: {outcome.message} — nothing moved (libmapper "
                                              "clamps nothing: give the map a range within the joint's limits)")
            else:
                self.count("commands")

        ask(self.bus, robot, "joints/set", {"names": names, "angles": angles, "speed": self.speed}, done,
            self.timeout)
