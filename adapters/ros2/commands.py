"""What a ROS 2 robot does with sonibus's commands: ``joints/set`` and ``posture`` become a
``trajectory_msgs/JointTrajectory`` for ros2_control's joint_trajectory_controller,
``stop`` the trajectory that holds the last positions; what a ROS robot has no standard
interface for (speech, behaviors, stiffness, awareness) is refused as ``unsupported``.

The owner has validated every request against the URDF's limits before these run.
A trajectory is one point: the controller's every joint (it refuses partial goals by
default), those not named held where they are, reached in the time the slowest named
joint needs at ``speed`` × its URDF velocity (``MIN_DURATION_S`` at least).

Why ``stop`` is a hold and not an empty trajectory: ROS 1's controller took an empty
trajectory as "stop", but ros2_controllers' (ros2_controllers#902, backported to
Humble) rejects empty trajectories as invalid, so an empty one would stop nothing.
A new trajectory replaces the running one from its start time (header stamp zero:
now), so one point at the last measured positions, ``stop_s`` away, halts it.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from sonibus.bus.errors import CommandError

from . import cdr
from .description import Description, wrap

MIN_DURATION_S = 0.1  # no controller should be asked to jump
UNSUPPORTED = {"behavior/run": "behaviors", "say": "speech", "stiffness": "stiffness", "awareness": "awareness"}


class Positions:
    """The latest position of each joint, as the robot reported it (any thread)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._values: dict[str, float] = {}
        self.t = 0.0  # when last updated (time.time())

    def update(self, values: dict[str, float]) -> None:
        with self._lock:
            self._values.update(values)
            self.t = time.time()

    def get(self, names: Sequence[str]) -> list[float | None]:
        with self._lock:
            return [self._values.get(n) for n in names]


class Ros2Verbs:
    """Every verb of ``sonibus.bus.verbs.RobotVerbs`` for a ROS 2 robot behind a trajectory controller."""

    def __init__(self, robot: str, description: Description, controller_joints: Sequence[str],
                 positions: Positions, send: Callable[[bytes], None], stop_s: float) -> None:
        self.robot, self.description = robot, description
        self.controller_joints = tuple(controller_joints)
        self.positions, self.send, self.stop_s = positions, send, stop_s

    # -- what a ROS robot does ------------------------------------------------------

    def joints_set(self, names: list[str], angles: list[float], speed: float) -> dict[str, Any]:
        for name in names:
            if not self.description.is_commanded(name):
                source = self.description.mimics[name].joint
                raise CommandError("bad_request", f"joints/set: {name} mimics {source} (it follows it): set {source}")
            if name not in self.controller_joints:
                raise CommandError("bad_request", f"joints/set: {name} is not among the controller's joints "
                                   f"({', '.join(self.controller_joints)}: key 'joints')")
        current = self.positions.get(self.controller_joints)
        unknown = [j for j, v in zip(self.controller_joints, current, strict=True) if v is None]
        if unknown:
            raise CommandError("failed", f"joints/set: no position of {', '.join(unknown)} heard from the robot yet: "
                               "without where it is, no safe duration for the move")
        target = dict(zip(self.controller_joints, current, strict=True))
        target.update(zip(names, angles, strict=True))
        seconds = max([MIN_DURATION_S, *(self._distance(n, target[n], here) /
                                         (speed * self.description.model.joint(n).max_velocity)
                                         for n, here in zip(self.controller_joints, current, strict=True))])
        self._trajectory([target[n] for n in self.controller_joints], seconds)  # type: ignore[misc]
        return {"duration_s": round(seconds, 3)}

    def posture(self, name: str, speed: float) -> dict[str, Any]:
        goal = self.description.model.posture(name)
        result = self.joints_set(list(goal), list(goal.values()), speed)
        return {"name": name, **result}

    def stop(self) -> dict[str, Any]:
        """Hold the last positions heard, ``stop_s`` from now; works with the ROS side gone (it only publishes)."""
        current = self.positions.get(self.controller_joints)
        if any(v is None for v in current):
            return {"held": False, "reason": "no joint state heard from the robot: sonibus has moved nothing"}
        self._trajectory(current, self.stop_s)  # type: ignore[arg-type]
        return {"held": True}

    def behavior_list(self) -> dict[str, Any]:
        return {"behaviors": []}

    def behavior_stop(self, name: str | None = None) -> dict[str, Any]:
        return {"was_running": False}

    # -- what it cannot ---------------------------------------------------------------

    def unsupported(self, verb: str) -> CommandError:
        """The refusal of a verb in ``UNSUPPORTED``."""
        return CommandError("unsupported", f"{verb}: robot '{self.robot}' is a ROS 2 robot, which has no standard "
                            f"interface for {UNSUPPORTED[verb]}; it takes joints/set, posture and stop")

    def behavior_run(self, name: str) -> dict[str, Any]:
        raise self.unsupported("behavior/run")

    def say(self, text: str, volume: float | None = None, speed: float | None = None) -> dict[str, Any]:
        raise self.unsupported("say")

    def stiffness(self, names: list[str], value: float) -> dict[str, Any]:
        raise self.unsupported("stiffness")

    def awareness(self, enabled: bool) -> dict[str, Any]:
        raise self.unsupported("awareness")

    # -- helpers ----------------------------------------------------------------------

    def _distance(self, joint: str, goal: float, here: float | None) -> float:
        delta = goal - (here or 0.0)
        return abs(wrap(delta) if joint in self.description.continuous else delta)

    def _trajectory(self, positions: Sequence[float], seconds: float) -> None:
        point = cdr.Point([float(p) for p in positions], seconds, [0.0] * len(positions))
        if not all(math.isfinite(p) for p in point.positions):
            raise CommandError("failed", "a position heard from the robot is not finite: nothing sent")
        self.send(cdr.joint_trajectory(cdr.Stamp(0, 0), self.controller_joints, [point]))
