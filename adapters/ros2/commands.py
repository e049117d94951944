"""What a ROS 2 robot does with sonibus's commands: ``joints/set`` and ``posture`` become a
``trajectory_msgs/JointTrajectory`` for ros2_control's joint_trajectory_controller (JTC),
``stop`` the trajectory JTC itself uses to stop and hold; what a ROS robot has no standard
interface for (speech, behaviors, stiffness, awareness) is refused as ``unsupported``.

Nothing heard from ROS becomes a target or shortens a move: anyone on the ROS graph can
publish ``/joint_states``. So

- a trajectory names only the joints the command names (JTC fills the others with where
  it holds them; it needs ``allow_partial_joints_goal: true`` for that, and without it
  refuses the trajectory and nothing moves: "Joints on incoming trajectory don't match
  the controller joints");
- its one point is within the URDF's limits (the owner has validated the request; checked
  again before sending), reached in the time the slowest named joint needs at ``speed`` ×
  its URDF velocity from the furthest place it could be within its limits (a continuous
  joint: half a turn, JTC's angle wraparound), ``MIN_DURATION_S`` at least;
- ``stop`` is the trajectory with no points: in JTC, ``set_hold_position()`` is that
  message (stamp zero, no points), which replaces the running trajectory and holds the
  joints where the controller has them (ros2_controllers' joint_trajectory_controller.cpp
  up to Humble's releases). Later releases build the hold from the controller's own state
  and refuse an empty trajectory sent on the topic ("Empty trajectory received."):
  docs/ros2.md says so, and what a stop needs there (the action's cancel).

A trajectory is sent only while the controller's subscription is matched (``matched``):
otherwise the command is ``not_connected`` (for ``stop``: not reached), never a reply
that says the robot did it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from sonibus.bus.errors import CommandError

from . import cdr
from .description import Description

MIN_DURATION_S = 0.1  # no controller should be asked to jump
UNSUPPORTED = {"behavior/run": "behaviors", "say": "speech", "stiffness": "stiffness", "awareness": "awareness"}


def reach_s(description: Description, joint: str, goal: float, speed: float) -> float:
    """The time ``joint`` needs to reach ``goal`` at ``speed`` × its URDF velocity from wherever
    within its limits it is (not from a heard position, which anyone can publish)."""
    spec = description.model.joint(joint)
    furthest = math.pi if joint in description.continuous else max(goal - spec.min, spec.max - goal)
    return furthest / (speed * spec.max_velocity)


class Ros2Verbs:
    """Every verb of ``sonibus.bus.verbs.RobotVerbs`` for a ROS 2 robot behind a trajectory controller."""

    def __init__(self, robot: str, description: Description, controller_joints: Sequence[str],
                 send: Callable[[bytes], None], matched: Callable[[], str]) -> None:
        """``matched()``: "" while the controller's subscription is matched, else why not."""
        self.robot, self.description = robot, description
        self.controller_joints = tuple(controller_joints)
        self.send, self.matched = send, matched

    # -- what a ROS robot does ------------------------------------------------------

    def joints_set(self, names: list[str], angles: list[float], speed: float) -> dict[str, Any]:
        for name in names:
            if not self.description.is_commanded(name):
                source = self.description.mimics[name].joint
                raise CommandError("bad_request", f"joints/set: {name} mimics {source} (it follows it): set {source}")
            if name not in self.controller_joints:
                raise CommandError("bad_request", f"joints/set: {name} is not among the controller's joints "
                                   f"({', '.join(self.controller_joints)}: key 'joints')")
        goal = dict(zip(names, angles, strict=True))
        seconds = max([MIN_DURATION_S, *(reach_s(self.description, n, v, speed) for n, v in goal.items())])
        self._trajectory("joints/set", tuple(goal), [cdr.Point(list(goal.values()), seconds, [0.0] * len(goal))])
        return {"targets": goal, "speed": speed, "duration_s": round(seconds, 3)}

    def posture(self, name: str, speed: float) -> dict[str, Any]:
        goal = self.description.model.posture(name)
        result = self.joints_set(list(goal), list(goal.values()), speed)
        return {"name": name, **result}

    def stop(self) -> dict[str, Any]:
        """JTC's stop-and-hold of before ros2_controllers#902 (no points); ``not_connected`` when no
        controller would get it. The answer says what is known: the hold was sent to a matched
        controller, not that the robot holds (since #902 the controller refuses it, and says so
        only in its own log)."""
        self._trajectory("stop", self.controller_joints, [])
        return {"hold_sent": True}

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

    def _trajectory(self, verb: str, names: Sequence[str], points: Sequence[cdr.Point]) -> None:
        for point in points:
            for name, value in zip(names, point.positions, strict=True):
                spec = self.description.model.joint(name)
                if not (math.isfinite(value) and spec.min <= value <= spec.max):
                    raise CommandError("failed", f"{verb}: {name} {value!r} is outside its URDF limits "
                                       f"[{spec.min:g}, {spec.max:g}]: nothing sent")
        unmatched = self.matched()
        if unmatched:
            raise CommandError("not_connected", f"{verb}: the trajectory reached no controller ({unmatched}): "
                               "nothing was sent")
        self.send(cdr.joint_trajectory(cdr.Stamp(0, 0), names, points))
