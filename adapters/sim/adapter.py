"""The simulated robot adapter: a Pepper or NAO that needs no robot."""

from __future__ import annotations

import math
import random
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sonibus.bus.commands import expand_stiffness_names
from sonibus.bus.errors import CommandError
from sonibus.bus.options import bad
from sonibus.bus.owner import RobotAdapter
from sonibus.bus.robot import load_model, models

from .behaviors import LIBRARY, Playback
from .motion import Body

IDLE_JOINTS = {"HeadYaw": (0.25, 9.0), "HeadPitch": (0.06, 6.0),
               "LShoulderPitch": (0.05, 4.5), "RShoulderPitch": (0.05, 4.7)}  # amplitude, period s


@dataclass(frozen=True)
class SimConfig:
    """Options of the ``sim`` adapter."""

    robot: str = "pepper"           # bus name of the robot
    model: str = ""                 # pepper | nao; default: the robot name without digits
    rate_hz: float = 100.0
    posture: str = "StandInit"      # where the robot starts
    idle: bool = False              # gentle breathing and looking around when nothing runs
    autoplay_s: float = 0.0         # run a random behavior every N seconds (0: never)
    words_per_minute: float = 150.0  # speaking rate at say speed 100

    def __post_init__(self) -> None:
        if not 0 < self.rate_hz <= 1000:
            raise bad("rate_hz", f"{self.rate_hz:g} must be in (0, 1000]")
        if self.model_name not in models():
            raise bad("model", f"'{self.model_name}' is unknown — known models: {', '.join(models())}")
        postures = load_model(self.model_name).postures
        if self.posture not in postures:
            raise bad("posture", f"'{self.posture}' is unknown for {self.model_name} — "
                      f"known postures: {', '.join(postures)}")

    @property
    def model_name(self) -> str:
        return self.model or self.robot.rstrip("0123456789")


class SimRobot(RobotAdapter):
    """Simulated Pepper or NAO: joints, behaviors, speech and postures, no robot needed."""

    Config = SimConfig

    def _open(self) -> None:
        cfg: SimConfig = self.config
        self.model = load_model(cfg.model_name)
        self.rate_hz = cfg.rate_hz
        self.body = Body(self.model, self.model.posture(cfg.posture))
        self._lock = threading.Lock()
        self._playback: Playback | None = None
        self._playback_started = 0.0
        self._posture: str | None = None
        self._speech: deque[tuple[str, float]] = deque()
        self._speaking_until = 0.0
        self._awareness = cfg.idle
        self._idle_home = self.body.pose()
        self._next_autoplay = time.monotonic() + cfg.autoplay_s
        self.frames_skipped = 0

    def behaviors(self) -> Sequence[str]:
        return sorted(LIBRARY)

    # -- the frame loop -----------------------------------------------------------

    def _acquire(self) -> None:
        period = 1.0 / self.rate_hz
        start = time.monotonic()
        frame = 0
        last = time.monotonic()
        while not self.stopping.is_set():
            now, tick = time.time(), time.monotonic()  # wall clock for `t`, monotonic for motion
            positions = self._advance(now, tick - last)
            last = tick
            self.publish_frame(now, frame, positions)
            frame += 1
            deadline = start + frame * period
            late = time.monotonic() - deadline
            if late > period:  # fell behind (VM stall): skip frames, never burst
                skipped = int(late / period)
                frame += skipped
                self.frames_skipped += skipped
                deadline = start + frame * period
            self.stopping.wait(max(0.0, deadline - time.monotonic()))

    def _advance(self, now: float, dt: float) -> list[float]:
        """Move the robot on by ``dt`` seconds; publish what happened; the new positions."""
        events: list[tuple[str, dict[str, Any]]] = []
        with self._lock:
            if self._playback is not None:
                targets, done = self._playback.targets(now - self._playback_started)
                self.body.set_targets(targets, 1.0)
                if done:
                    events.append(("behavior", {"name": self._playback.behavior.name, "state": "stopped"}))
                    self._playback = None
            elif self._posture is not None and not self.body.moving():
                events.append(("posture", {"name": self._posture, "state": "reached"}))
                self._posture = None
            elif self.config.idle:
                self._idle(now)
            if self.config.autoplay_s and self._playback is None and time.monotonic() >= self._next_autoplay:
                self._next_autoplay = time.monotonic() + self.config.autoplay_s
                events.extend(self._start_behavior(random.choice(list(LIBRARY)), now))
            self.body.step(max(0.0, min(dt, 0.1)))
            if self._speaking_until and now >= self._speaking_until:
                events.append(("speech", {"text": self._speech.popleft()[0], "state": "done"}))
                self._speaking_until = 0.0
            if not self._speaking_until and self._speech:
                text, duration = self._speech[0]
                self._speaking_until = now + duration
                events.append(("speech", {"text": text, "state": "started"}))
            self._emit(events)
            return list(self.body.positions)

    def _idle(self, now: float) -> None:
        targets = {}
        for joint, (amplitude, period) in IDLE_JOINTS.items():
            if self.model.has_joint(joint) and (joint != "HeadYaw" or self._awareness):
                targets[joint] = self._idle_home[joint] + amplitude * math.sin(2 * math.pi * now / period)
        self.body.set_targets(targets, 0.2)

    def _start_behavior(self, name: str, now: float) -> list[tuple[str, dict[str, Any]]]:
        events = self._interrupt()
        self._playback = Playback(LIBRARY[name], self.body.pose())
        self._playback_started = now
        events.append(("behavior", {"name": name, "state": "started"}))
        return events

    def _end_behavior(self) -> list[tuple[str, dict[str, Any]]]:
        if self._playback is None:
            return []
        name = self._playback.behavior.name
        self._playback = None
        return [("behavior", {"name": name, "state": "stopped"})]

    def _interrupt(self) -> list[tuple[str, dict[str, Any]]]:
        events = self._end_behavior()
        if self._posture is not None:
            events.append(("posture", {"name": self._posture, "state": "interrupted"}))
            self._posture = None
        self._idle_home = self.body.pose()
        return events

    def _emit(self, events: list[tuple[str, dict[str, Any]]]) -> None:
        """Publish events; callers hold the lock, so events keep the order of what happened."""
        for kind, fields in events:
            self.publish_event(kind, **fields)

    # -- commands (validated by RobotAdapter before they get here) ----------------

    def _cmd_behavior_run(self, name: str) -> dict[str, Any]:
        with self._lock:
            if self._playback is not None and self._playback.behavior.name == name:
                raise CommandError("failed", f"behavior '{name}' is already running")
            self._emit(self._start_behavior(name, time.time()))
        return {"name": name, "duration": LIBRARY[name].duration}

    def _cmd_behavior_stop(self, name: str | None = None) -> dict[str, Any]:
        with self._lock:
            running = self._playback is not None and name in (None, self._playback.behavior.name)
            if running:
                self._emit(self._end_behavior())
                self.body.halt()
        return {"was_running": running}

    def _cmd_joints_set(self, names: list[str], angles: list[float], speed: float) -> dict[str, Any]:
        with self._lock:
            self._emit(self._interrupt())
            self.body.set_targets(dict(zip(names, map(float, angles), strict=True)), speed)
            self._idle_home.update(zip(names, map(float, angles), strict=True))
        return {}

    def _cmd_posture(self, name: str, speed: float) -> dict[str, Any]:
        with self._lock:
            self._emit([*self._interrupt(), ("posture", {"name": name, "state": "started"})])
            pose = self.model.posture(name)
            self.body.set_targets(pose, speed)
            self._idle_home.update(pose)
            self._posture = name
        return {"name": name}

    def _cmd_say(self, text: str, volume: float | None = None, speed: float | None = None) -> dict[str, Any]:
        words = max(len(text.split()), len(text) / 6.0)  # long unbroken text still takes time
        duration = 0.2 + words * 60.0 / (self.config.words_per_minute * (speed or 100.0) / 100.0)
        with self._lock:
            self._speech.append((text, duration))
            queued = len(self._speech) - 1
        return {"duration": round(duration, 3), "queued": queued}

    def _cmd_stiffness(self, names: list[str], value: float) -> dict[str, Any]:
        joints = expand_stiffness_names(names, self.model)
        with self._lock:
            self.body.set_stiffness(joints, float(value))
        return {"joints": joints}

    def _cmd_awareness(self, enabled: bool) -> dict[str, Any]:
        with self._lock:
            previous, self._awareness = self._awareness, enabled
        return {"enabled": enabled, "previous": previous}

    def _cmd_stop(self) -> dict[str, Any]:
        with self._lock:
            events = self._interrupt()
            self.body.halt()
            if self._speaking_until:
                events.append(("speech", {"text": self._speech[0][0], "state": "done"}))
            self._speech.clear()
            self._speaking_until = 0.0
            self._emit(events)
        return {}
