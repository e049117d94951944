"""Built-in behaviors of the simulator: keyframe trajectories named like NAOqi's
animations, for joints Pepper and NAO share (head and arms).

A behavior starts from wherever the robot is, passes its keyframes with smooth
(cosine) easing and returns to where it started. The body's speed limits apply
on top, so no keyframe can move a joint faster than the real robot could.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass

Pose = dict[str, float]

_MIRROR = {"ShoulderPitch": 1, "ShoulderRoll": -1, "ElbowYaw": -1, "ElbowRoll": -1, "WristYaw": -1, "Hand": 1}


def _right(**angles: float) -> Pose:
    return {"R" + k: v for k, v in angles.items()}


def _both(**right: float) -> Pose:
    """A symmetric pose given by its right arm."""
    pose = _right(**right)
    pose.update({"L" + k: v * _MIRROR[k] for k, v in right.items()})
    return pose


@dataclass(frozen=True)
class Behavior:
    """A named keyframe trajectory: ``(seconds from start, pose)`` pairs."""

    name: str
    keyframes: tuple[tuple[float, Pose], ...]
    settle_s: float = 0.8

    @property
    def joints(self) -> tuple[str, ...]:
        return tuple(sorted({j for _, pose in self.keyframes for j in pose}))

    @property
    def duration(self) -> float:
        return self.keyframes[-1][0] + self.settle_s


class Playback:
    """One run of a behavior from ``start`` pose: targets as a function of time."""

    def __init__(self, behavior: Behavior, start: Mapping[str, float]) -> None:
        self.behavior = behavior
        joints = behavior.joints
        home = {j: start[j] for j in joints if j in start}
        keyframes: list[tuple[float, Pose]] = [(0.0, dict(home))]
        for t, pose in behavior.keyframes:
            merged = dict(keyframes[-1][1])
            merged.update({j: v for j, v in pose.items() if j in home})
            keyframes.append((t, merged))
        keyframes.append((behavior.duration, dict(home)))
        self._keyframes = keyframes

    def targets(self, elapsed: float) -> tuple[Pose, bool]:
        """Targets at ``elapsed`` seconds, and whether the behavior is over."""
        keyframes = self._keyframes
        if elapsed >= keyframes[-1][0]:
            return dict(keyframes[-1][1]), True
        for (t0, a), (t1, b) in itertools.pairwise(keyframes):
            if elapsed < t1:
                x = (elapsed - t0) / (t1 - t0)
                ease = 0.5 - 0.5 * math.cos(math.pi * x)
                return {j: a[j] + (b[j] - a[j]) * ease for j in a}, False
        return dict(keyframes[-1][1]), True  # unreachable: the last keyframe ends the loop


def _wave() -> tuple[tuple[float, Pose], ...]:
    up = _right(ShoulderPitch=-0.9, ShoulderRoll=-0.3, ElbowYaw=1.5, ElbowRoll=1.2, Hand=0.95)
    frames: list[tuple[float, Pose]] = [(0.7, {**up, "HeadYaw": -0.25, "HeadPitch": -0.15})]
    for i in range(4):
        frames.append((1.1 + 0.4 * i, _right(ElbowRoll=0.5 if i % 2 == 0 else 1.2,
                                             ShoulderRoll=-0.55 if i % 2 == 0 else -0.25)))
    return tuple(frames)


LIBRARY: dict[str, Behavior] = {b.name: b for b in (
    Behavior("animations/Stand/Gestures/Hey_1", _wave()),
    Behavior("animations/Stand/Gestures/Enthusiastic_4", (
        (0.6, {**_both(ShoulderPitch=-0.6, ShoulderRoll=-0.5, ElbowRoll=0.4, Hand=0.9), "HeadPitch": -0.3}),
        (1.1, _both(ShoulderPitch=-0.2, ShoulderRoll=-0.9, ElbowRoll=0.9)),
        (1.6, _both(ShoulderPitch=-0.7, ShoulderRoll=-0.4, ElbowRoll=0.3)),
        (2.1, _both(ShoulderPitch=-0.2, ShoulderRoll=-0.9, ElbowRoll=0.9)),
    )),
    Behavior("animations/Stand/Gestures/ShowSky_1", (
        (0.9, {**_right(ShoulderPitch=-1.2, ShoulderRoll=-0.2, ElbowYaw=1.0, ElbowRoll=0.2, Hand=0.8),
               "HeadPitch": -0.4, "HeadYaw": -0.2}),
        (2.2, {"HeadPitch": -0.35, "HeadYaw": 0.1}),
    )),
    Behavior("animations/Stand/Gestures/Explain_1", (
        (0.7, _both(ShoulderPitch=0.6, ShoulderRoll=-0.25, ElbowYaw=1.6, ElbowRoll=0.8, WristYaw=1.2, Hand=0.9)),
        (1.3, _both(ShoulderPitch=0.8, ShoulderRoll=-0.45, ElbowRoll=0.5)),
        (1.9, _both(ShoulderPitch=0.6, ShoulderRoll=-0.2, ElbowRoll=0.9)),
    )),
    Behavior("animations/Stand/Gestures/No_3", (
        (0.35, {"HeadYaw": 0.45}), (0.75, {"HeadYaw": -0.45}), (1.15, {"HeadYaw": 0.4}), (1.55, {"HeadYaw": -0.3}),
    ), settle_s=0.5),
    Behavior("animations/Stand/Gestures/Yes_1", (
        (0.3, {"HeadPitch": 0.3}), (0.6, {"HeadPitch": -0.15}), (0.9, {"HeadPitch": 0.3}), (1.2, {"HeadPitch": -0.1}),
    ), settle_s=0.5),
    Behavior("animations/Stand/Emotions/Positive/Happy_4", (
        (0.5, {**_both(ShoulderPitch=0.3, ShoulderRoll=-0.6, ElbowRoll=1.2, Hand=0.8), "HeadPitch": -0.25}),
        (0.8, {**_both(ShoulderRoll=-0.3), "HeadYaw": 0.25}),
        (1.1, {**_both(ShoulderRoll=-0.7), "HeadYaw": -0.25}),
        (1.4, {**_both(ShoulderRoll=-0.3), "HeadYaw": 0.2}),
        (1.7, {**_both(ShoulderRoll=-0.7), "HeadYaw": 0.0}),
    )),
    Behavior("animations/Stand/Gestures/BowShort_1", (
        (0.8, {"HeadPitch": 0.4, **_both(ShoulderPitch=1.6, ShoulderRoll=-0.1, ElbowRoll=0.3)}),
        (1.6, {"HeadPitch": 0.4}),
    )),
)}
