"""The simulated robot itself, with no bus: motion, behaviors, postures and
speech, advanced frame by frame. It carries out the robot verbs
(``sonibus.bus.verbs.RobotVerbs``) for ``SimRobot``, which puts it on the bus;
the NAOqi face serves it as fake NAOqi services. Events go to ``emit(kind, fields)``,
called under the engine's lock so they keep the order of what happened."""

from __future__ import annotations

import math
import random
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from sonibus.bus.commands import expand_stiffness_names
from sonibus.bus.errors import CommandError
from sonibus.bus.robot import RobotModel

from .behaviors import LIBRARY, Playback
from .motion import Body

IDLE_JOINTS = {"HeadYaw": (0.25, 9.0), "HeadPitch": (0.06, 6.0),
               "LShoulderPitch": (0.05, 4.5), "RShoulderPitch": (0.05, 4.7)}  # amplitude, period s

Emit = Callable[[str, dict[str, Any]], None]


@dataclass(eq=False)
class Utterance:
    """A text to speak, how long it takes, and how many texts were ahead of it."""

    text: str
    duration: float
    queued: int = 0


class SimEngine:
    """One simulated robot's state; every method is thread-safe."""

    def __init__(self, model: RobotModel, emit: Emit, *, posture: str = "StandInit", idle: bool = False,
                 autoplay_s: float = 0.0, words_per_minute: float = 150.0) -> None:
        self.model = model
        self.body = Body(model, model.posture(posture) if posture in model.postures else {})
        self.lock = threading.RLock()
        self._emit_one = emit
        self.idle, self.autoplay_s, self.words_per_minute = idle, autoplay_s, words_per_minute
        self._playback: Playback | None = None
        self._playback_started = 0.0
        self._posture: str | None = None
        self._last_posture: tuple[str, str] | None = None
        self._speech: deque[Utterance] = deque()
        self._speaking_until = 0.0
        self.aware = idle  # basic awareness: idle looking around
        self._idle_home = self.body.pose()
        self.halted = False  # a stop holds the body still (no idle motion, no autoplay) until the next move
        self._next_autoplay = time.monotonic() + autoplay_s
        # the last step's positions before it and its length: speeds are worked out when asked
        # (by the microphones, while anyone listens), not every frame for nobody
        self._before: list[float] = list(self.body.positions)
        self._dt = 0.0
        # the idle joints this model has: (name, amplitude, angular frequency), found once
        self._idle_joints = [(joint, amplitude, 2 * math.pi / period) for joint, (amplitude, period)
                             in IDLE_JOINTS.items() if model.has_joint(joint)]

    @staticmethod
    def behaviors() -> list[str]:
        return sorted(LIBRARY)

    @property
    def running_behavior(self) -> str | None:
        playback = self._playback
        return playback.behavior.name if playback is not None else None

    @property
    def speaking(self) -> bool:
        return bool(self._speaking_until or self._speech)

    def still_to_say(self, utterance: Utterance) -> bool:
        """Whether ``utterance`` is queued or being spoken."""
        with self.lock:
            return any(entry is utterance for entry in self._speech)

    # -- time ---------------------------------------------------------------------

    def advance(self, now: float, dt: float) -> list[float]:
        """Move on by ``dt`` seconds (wall time ``now``); the new positions."""
        events: list[tuple[str, dict[str, Any]]] = []
        with self.lock:
            if self._playback is not None:
                targets, done = self._playback.targets(now - self._playback_started)
                self.body.set_targets(targets, 1.0)
                if done:
                    events.append(("behavior", {"name": self._playback.behavior.name, "state": "stopped",
                                                "end": "finished"}))
                    self._playback = None
            elif self._posture is not None and not self.body.moving():
                events.append(("posture", {"name": self._posture, "state": "reached"}))
                self._last_posture = (self._posture, "reached")
                self._posture = None
            elif self.idle and not self.halted:
                self._idle(now)
            if (self.autoplay_s and self._playback is None and not self.halted
                    and time.monotonic() >= self._next_autoplay):
                self._next_autoplay = time.monotonic() + self.autoplay_s
                events.extend(self._start_behavior(random.choice(list(LIBRARY)), now))
            self._step(max(0.0, min(dt, 0.1)))
            if self._speaking_until and now >= self._speaking_until:
                events.append(("speech", {"text": self._speech.popleft().text, "state": "done"}))
                self._speaking_until = 0.0
            if not self._speaking_until and self._speech:
                self._speaking_until = now + self._speech[0].duration
                events.append(("speech", {"text": self._speech[0].text, "state": "started"}))
            if events:
                self._emit(events)
            return list(self.body.positions)

    def speeds(self) -> dict[str, float]:
        """Each moving joint's speed over the last step (rad/s, signed): what the body sound follows."""
        with self.lock:
            dt = self._dt
            if dt <= 0:
                return {}
            return {name: (after - was) / dt for name, was, after
                    in zip(self.body.names, self._before, self.body.positions, strict=True) if after != was}

    def _step(self, dt: float) -> None:
        if dt <= 0:
            return
        self._before[:] = self.body.positions
        self._dt = dt
        self.body.step(dt)

    def _idle(self, now: float) -> None:
        home, aware, sin = self._idle_home, self.aware, math.sin
        self.body.set_targets({joint: home[joint] + amplitude * sin(omega * now)
                               for joint, amplitude, omega in self._idle_joints
                               if aware or joint != "HeadYaw"}, 0.2)

    def _start_behavior(self, name: str, now: float) -> list[tuple[str, dict[str, Any]]]:
        events = self._interrupt()
        self.halted = False
        self._playback = Playback(LIBRARY[name], self.body.pose())
        self._playback_started = now
        events.append(("behavior", {"name": name, "state": "started"}))
        return events

    def _end_behavior(self) -> list[tuple[str, dict[str, Any]]]:
        if self._playback is None:
            return []
        name = self._playback.behavior.name
        self._playback = None
        return [("behavior", {"name": name, "state": "stopped", "end": "cut"})]

    def _interrupt(self) -> list[tuple[str, dict[str, Any]]]:
        events = self._end_behavior()
        if self._posture is not None:
            events.append(("posture", {"name": self._posture, "state": "interrupted"}))
            self._last_posture = (self._posture, "interrupted")
            self._posture = None
        self._idle_home = self.body.pose()
        return events

    def _emit(self, events: list[tuple[str, dict[str, Any]]]) -> None:
        for kind, fields in events:
            self._emit_one(kind, fields)

    # -- the verbs (validated before they get here) -----------------------------------

    def behavior_list(self) -> dict[str, Any]:
        return {"behaviors": self.behaviors()}

    def behavior_run(self, name: str) -> dict[str, Any]:
        with self.lock:
            if self.running_behavior == name:
                raise CommandError("failed", f"behavior '{name}' is already running")
            self._emit(self._start_behavior(name, time.time()))
        return {"name": name, "duration": round(LIBRARY[name].duration, 3)}  # (3.1 s, not 3.1000000000000005)

    def behavior_stop(self, name: str | None = None) -> dict[str, Any]:
        with self.lock:
            running = self._playback is not None and name in (None, self._playback.behavior.name)
            if running:
                self._emit(self._end_behavior())
                self.body.halt()
        return {"was_running": running}

    def joints_set(self, names: Sequence[str], angles: Sequence[float], speed: float) -> dict[str, Any]:
        targets = dict(zip(names, map(float, angles), strict=True))
        with self.lock:
            self._emit(self._interrupt())
            self.halted = False
            self.body.set_targets(targets, speed)
            self._idle_home.update(targets)
        return {"targets": targets, "speed": speed}  # (what it moves to: within the limits, by validation)

    def posture(self, name: str, speed: float) -> dict[str, Any]:
        with self.lock:
            self._emit([*self._interrupt(), ("posture", {"name": name, "state": "started"})])
            self.halted = False
            pose = self.model.posture(name)
            self.body.set_targets(pose, speed)
            self._idle_home.update(pose)
            self._posture = name
        return {"name": name}

    def posture_done(self, name: str) -> bool | None:
        """None while posture ``name`` is under way, then whether it was reached (not interrupted)."""
        with self.lock:
            if self._posture == name:
                return None
            return self._last_posture == (name, "reached")

    def say(self, text: str, volume: float | None = None, speed: float | None = None) -> dict[str, Any]:
        utterance = self.speak(text, volume, speed)
        return {"duration": round(utterance.duration, 3), "queued": utterance.queued}

    def speak(self, text: str, volume: float | None = None, speed: float | None = None) -> Utterance:
        """Queue ``text``; the utterance, to wait for with ``still_to_say``."""
        words = max(len(text.split()), len(text) / 6.0)  # long unbroken text still takes time
        duration = 0.2 + words * 60.0 / (self.words_per_minute * (speed or 100.0) / 100.0)
        with self.lock:
            utterance = Utterance(text, duration, len(self._speech))
            self._speech.append(utterance)
        return utterance

    def stiffness(self, names: Sequence[str], value: float) -> dict[str, Any]:
        joints = expand_stiffness_names(names, self.model)
        with self.lock:
            self.body.set_stiffness(joints, float(value))
        return {"joints": joints}

    def awareness(self, enabled: bool) -> dict[str, Any]:
        with self.lock:
            previous, self.aware = self.aware, enabled
        return {"enabled": enabled, "previous": previous}

    def stop(self, speech: bool = True, motion: bool = True) -> dict[str, Any]:
        """Halt: ``{"held": True, "cut": [the behaviors it ended], "silenced": texts dropped}``."""
        with self.lock:
            events = self._interrupt() if motion else []
            cut = [fields["name"] for kind, fields in events if kind == "behavior"]
            silenced = len(self._speech) if speech else 0
            if motion:
                # (a real robot's breathing may go on; an operator's STOP means still: idle motion and
                # autoplay wait for the next behavior, posture or joint move)
                self.halted = True
                self.body.halt()
            if speech:
                if self._speaking_until:
                    events.append(("speech", {"text": self._speech[0].text, "state": "done"}))
                self._speech.clear()
                self._speaking_until = 0.0
            self._emit(events)
        return {"held": motion, "cut": cut, "silenced": silenced}
