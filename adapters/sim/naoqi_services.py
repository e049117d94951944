"""Fake NAOqi services over a ``SimEngine``, as a real robot answers them
(naoqi-notes.md): float32 values, blocking calls that block, a body-name order
that is not the joint table's, remote errors as ``RuntimeError``."""

from __future__ import annotations

import functools
import struct
import time
from collections.abc import Callable
from typing import Any

import qi

from sonibus.bus.errors import CommandError

from .engine import SimEngine

MEMORY = "Device/SubDeviceList/{}/{}"
QUANTITIES = {"Position/Sensor/Value": "pos", "Position/Actuator/Value": "cmd",
              "ElectricCurrent/Sensor/Value": "cur", "Temperature/Sensor/Value": "temp"}


def f32(value: float) -> float:
    return struct.unpack("f", struct.pack("f", value))[0]


def delayed(method: Callable[..., Any]) -> Callable[..., Any]:
    """Every call costs the endpoint's simulated network delay (and waits while it is frozen);
    engine refusals become remote errors. Counted while in flight (``FakeNaoqi.serving``): the
    fake's stop waits for them, since a call libqi's threads are still running in Python when
    the interpreter exits crashes the process."""
    @functools.wraps(method)
    def call(self: Any, *args: Any) -> Any:
        with self.fake.serving(method.__qualname__):
            if not self.fake.wait_answering():
                raise RuntimeError(f"{method.__qualname__}: NAOqi is shutting down")
            if self.fake.delay_s:
                time.sleep(self.fake.delay_s)
            try:
                return method(self, *args)
            except CommandError as exc:
                raise RuntimeError(exc.message) from None
    return call


class _Service:
    def __init__(self, fake: Any) -> None:
        self.fake = fake

    @property
    def engine(self) -> SimEngine:
        return self.fake.engine


@qi.multiThreaded()
class Subscriber:
    """What ``ALMemory.subscriber(key)`` returns: an object with a ``signal``."""

    def __init__(self) -> None:
        self.signal = qi.Signal()


@qi.multiThreaded()
class ALMemory(_Service):
    def __init__(self, fake: Any) -> None:
        super().__init__(fake)
        self.subscribers: dict[str, list[Subscriber]] = {}

    @delayed
    def getData(self, key: str) -> Any:
        return self.fake.memory_value(key)

    @delayed
    def getListData(self, keys: list[str]) -> list[Any]:
        return [self.fake.memory_value(k) for k in keys]

    @delayed
    def subscriber(self, key: str) -> Subscriber:
        if self.fake.config.subscriber == "invalid-signature":
            raise RuntimeError("Invalid signature")  # what qi 3.x against NAOqi 2.5 reportedly gets
        subscriber = Subscriber()
        self.subscribers.setdefault(key, []).append(subscriber)
        return subscriber

    def raise_event(self, key: str, value: Any) -> None:
        self.fake.memory[key] = value
        for subscriber in self.subscribers.get(key, []):
            subscriber.signal(value)


@qi.multiThreaded()
class ALMotion(_Service):
    @delayed
    def getBodyNames(self, chain: str) -> list[str]:
        return list(self.fake.body_names)

    @delayed
    def getLimits(self, name: str) -> list[list[float]]:
        joints = self.engine.model.joint_names if name == "Body" else [name]
        return [[f32(j.min), f32(j.max), f32(j.max_velocity), 1.0]
                for j in (self.engine.model.joint(n) for n in joints)]

    @delayed
    def getAngles(self, names: list[str], use_sensors: bool) -> list[float]:
        pose = self.engine.body.pose()
        return [f32(pose[n]) for n in self.fake.expand(names)]

    @delayed
    def setAngles(self, names: Any, angles: Any, fraction: float) -> None:
        names, angles = _listed(names), _listed(angles)
        self.engine.joints_set(names, angles, fraction)

    @delayed
    def angleInterpolationWithSpeed(self, names: Any, angles: Any, fraction: float) -> None:
        names = _listed(names)
        self.engine.joints_set(names, _listed(angles), fraction)
        self.fake.until(lambda: not self.engine.body.moving(names), "ALMotion::angleInterpolationWithSpeed")

    @delayed
    def setStiffnesses(self, names: Any, value: Any) -> None:
        value = value[0] if isinstance(value, list) else value
        self.engine.stiffness(_listed(names), float(value))

    @delayed
    def getStiffnesses(self, names: Any) -> list[float]:
        index = {n: i for i, n in enumerate(self.engine.model.joint_names)}
        return [self.engine.body.stiffness[index[n]] for n in self.fake.expand(_listed(names))]

    @delayed
    def wakeUp(self) -> None:
        self.engine.stiffness(["Body"], 1.0)

    @delayed
    def rest(self) -> None:
        self.engine.stiffness(["Body"], 0.0)

    @delayed
    def killAll(self) -> None:
        self.engine.stop(speech=False)

    @delayed
    def stopMove(self) -> None:
        self.engine.stop(speech=False)


@qi.multiThreaded()
class ALRobotPosture(_Service):
    @delayed
    def getPostureList(self) -> list[str]:
        return sorted(self.engine.model.postures)

    @delayed
    def goToPosture(self, name: str, speed: float) -> bool:
        if name not in self.engine.model.postures:
            raise RuntimeError(f"ALRobotPosture::goToPosture: unknown posture {name}")
        self.engine.posture(name, speed)
        self.fake.until(lambda: self.engine.posture_done(name) is not None, "ALRobotPosture::goToPosture")
        return bool(self.engine.posture_done(name))  # False when interrupted, as NAOqi answers

    @delayed
    def stopMove(self) -> None:
        self.engine.stop(speech=False)


@qi.multiThreaded()
class ALBehaviorManager(_Service):
    def __init__(self, fake: Any) -> None:
        super().__init__(fake)
        self.behaviorStarted = qi.Signal("(s)")
        self.behaviorStopped = qi.Signal("(s)")

    @delayed
    def getInstalledBehaviors(self) -> list[str]:
        return self.engine.behaviors()

    @delayed
    def isBehaviorInstalled(self, name: str) -> bool:
        return name in self.engine.behaviors()

    @delayed
    def isBehaviorRunning(self, name: str) -> bool:
        return self.engine.running_behavior == name

    @delayed
    def getRunningBehaviors(self) -> list[str]:
        running = self.engine.running_behavior
        return [running] if running else []

    @delayed
    def startBehavior(self, name: str) -> None:
        if name not in self.engine.behaviors():
            raise RuntimeError(f"Behavior not found: {name}")
        self.engine.behavior_run(name)

    @delayed
    def runBehavior(self, name: str) -> None:
        self.startBehavior(name)
        self.fake.until(lambda: self.engine.running_behavior != name, "ALBehaviorManager::runBehavior")

    @delayed
    def stopBehavior(self, name: str) -> None:
        self.engine.behavior_stop(name)

    @delayed
    def stopAllBehaviors(self) -> None:
        self.engine.behavior_stop(None)


@qi.multiThreaded()
class ALTextToSpeech(_Service):
    def __init__(self, fake: Any) -> None:
        super().__init__(fake)
        self.volume = 1.0
        self.parameters = {"speed": 100.0, "pitchShift": 1.0}

    @delayed
    def say(self, text: str) -> None:
        utterance = self.engine.speak(text, self.volume, self.parameters["speed"])
        # returns when this text is spoken, as NAOqi does
        self.fake.until(lambda: not self.engine.still_to_say(utterance), "ALTextToSpeech::say")

    @delayed
    def setVolume(self, volume: float) -> None:
        self.volume = float(volume)

    @delayed
    def getVolume(self) -> float:
        return self.volume

    @delayed
    def setParameter(self, name: str, value: float) -> None:
        self.parameters[name] = float(value)

    @delayed
    def getParameter(self, name: str) -> float:
        return self.parameters[name]

    @delayed
    def stopAll(self) -> None:
        self.engine.stop(motion=False)


@qi.multiThreaded()
class ALSystem(_Service):
    @delayed
    def systemVersion(self) -> str:
        return self.fake.config.naoqi_version

    @delayed
    def robotName(self) -> str:
        return self.fake.config.robot_name


@qi.multiThreaded()
class ALBasicAwareness(_Service):
    def __init__(self, fake: Any) -> None:
        super().__init__(fake)
        self.paused = False

    @delayed
    def setEnabled(self, enabled: bool) -> None:
        self.engine.awareness(bool(enabled))

    @delayed
    def isEnabled(self) -> bool:
        return self.engine.aware

    @delayed
    def pauseAwareness(self) -> None:
        self.paused = True

    @delayed
    def resumeAwareness(self) -> None:
        self.paused = False

    @delayed
    def isAwarenessPaused(self) -> bool:
        return self.paused


def _listed(value: Any) -> list[Any]:
    return list(value) if isinstance(value, list | tuple) else [value]


SERVICES = (ALMemory, ALMotion, ALRobotPosture, ALBehaviorManager, ALTextToSpeech, ALBasicAwareness, ALSystem)
