"""The ``ros2`` robot adapter: a ROS 2 robot on the sonibus bus, described by its URDF.

Its ``sensor_msgs/JointState`` topic becomes the robot's frames (joints under their
URDF names, ``t`` from the header stamp), over rmw_zenoh (``middleware = "zenoh"``:
the topic is Zenoh traffic) or a DDS (``"dds"``, Cyclone DDS: the ``ros2-dds`` extra);
``joints/set``, ``posture`` and ``stop`` go back as ``trajectory_msgs/JointTrajectory``
to a joint_trajectory_controller, validated against the URDF's limits first.
docs/ros2.md has the installation keys and a first-connection checklist.
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Any

from sonibus.bus import ConfigError
from sonibus.bus.owner import RobotAdapter

from . import cdr
from .commands import UNSUPPORTED, Ros2Verbs
from .config import Ros2Config
from .description import Description, describe, wrap
from .urdf import UrdfError, group_states, parse
from .zenoh_link import BadInput, Received, RosSession, ZenohLink

log = logging.getLogger(__name__)
LIMIT_SLACK = 0.01  # rad or m past a URDF limit a robot may report (encoder noise at an end stop)
SILENCE_S = 3.0  # no JointState this long after the start: the link says why (DDS: matched or not)
MAX_NAMED = 128  # unknown joint names remembered for their one warning (the names come from the network)

__all__ = ["Ros2Config", "Ros2Robot", "Ros2Verbs"]


class Ros2Robot(RobotAdapter):
    """A ROS 2 robot: its joint states in, trajectories to its controller out."""

    Config = Ros2Config
    Verbs = Ros2Verbs
    verbs: Ros2Verbs
    counters = ("joint_states", "unknown_joints", "ros_lost", "restamped")

    def _open(self) -> None:
        c = self.config
        self.link = self._link()
        self.description = self._describe(self._urdf_text())
        self.model, self.rate_hz = self.description.model, c.rate_hz
        commanded = [j for j in self.model.joint_names if self.description.is_commanded(j)]
        for joint in c.joints:
            if joint not in commanded:
                raise ConfigError(f"{self._at('joints')}: '{joint}' is not a movable, non-mimic joint of the URDF "
                                  f"— those are: {', '.join(commanded)}")
        self.verbs = Ros2Verbs(self.robot, self.description, c.joints or commanded, self.link.send,
                               getattr(self.link, "matched", _matched))
        self._seq = 0
        self._unknown: set[str] = set()
        self._dropped = 0
        log.info("%s: robot '%s' from %s: %d joints (%s), chains: %s; joint states from %s on %s, "
                 "trajectories to %s", self.name, self.robot, self.model.description, len(self.model.joints),
                 ", ".join(self.model.joint_names), ", ".join(c.chains) or "none", c.joint_states, self.link.where,
                 c.controller)

    def _at(self, key: str) -> str:
        return self.where(key) if self.where else f"node '{self.name}' key '{key}'"

    def _link(self) -> Any:
        if self.config.middleware == "dds":
            from .dds_link import DdsLink  # Cyclone DDS: the ros2-dds extra
            return self.own(DdsLink(self.config))
        bus = self.bus
        if self.config.router:
            bus = self.own(RosSession(self.config.router, self.bus)).bus
        link = ZenohLink(bus, self.config, self._graph)
        self.own(link)
        self.own(link.queue)  # its drops (a flood) are the node's `dropped`
        link.open()
        return link

    def _urdf_text(self) -> tuple[str, str]:
        c = self.config
        if c.urdf == "topic":
            try:
                return self.link.description(c.description_timeout_s), f"{c.description_topic} of the robot"
            except BadInput as exc:
                raise ConfigError(f"{self._at('urdf')}: {exc}") from None
        path = Path(self.resolve(c.urdf))
        try:
            return path.read_text(encoding="utf-8"), str(path)
        except OSError as exc:
            raise ConfigError(f"{self._at('urdf')}: cannot read URDF {path}: {exc.strerror}") from None

    def _describe(self, urdf: tuple[str, str]) -> Description:
        c = self.config
        try:
            srdf = self.resolve(c.srdf)
            postures = group_states(Path(srdf).read_text(encoding="utf-8"), srdf) if srdf else {}
            postures.update(c.postures)
            return describe(parse(urdf[0], urdf[1]), c.chains, postures, c.chain_root, c.default_velocity)
        except UrdfError as exc:
            raise ConfigError(f"{self._at('urdf')}: {exc}") from None
        except OSError as exc:
            raise ConfigError(f"{self._at('srdf')}: cannot read SRDF {c.srdf}: {exc.strerror}") from None

    def robot_info(self) -> dict[str, Any]:
        info = super().robot_info()
        for joint in info["joints"]:
            if not joint["chain"]:  # in none of the chains the installation names
                del joint["chain"]
        if self.description.kinematics is not None:
            info["kinematics"] = self.description.kinematics
        info["controller"] = self.controller()
        return info

    def served_verbs(self) -> tuple[str, ...]:
        return tuple(verb for verb in super().served_verbs() if verb not in UNSUPPORTED)

    def controller(self) -> dict[str, Any]:
        """The trajectory controller as this node sees it: its topic, and whether its subscription
        is matched (``why`` not, otherwise): commands reach it only then."""
        unmatched = self.verbs.matched() if hasattr(self, "verbs") else "not started"
        shown: dict[str, Any] = {"topic": self.config.controller, "matched": not unmatched}
        if unmatched:
            shown["why"] = unmatched
        return shown

    def describe(self) -> dict[str, Any]:
        described = super().describe()
        described["controller"] = self.controller()
        return described

    def execute(self, verb: str, args: Any) -> dict[str, Any]:
        """A verb a ROS robot has no interface for is refused as such before its arguments are
        checked (``behavior/run`` would otherwise be an unknown behavior)."""
        if verb in UNSUPPORTED:
            self.ownership.check(verb)
            raise self.verbs.unsupported(verb)
        return super().execute(verb, args)

    def _graph(self, key: str, alive: bool) -> None:
        chunks = key.split("/")
        what = {"NN": "node", "MP": "publisher", "MS": "subscription", "SS": "service", "SC": "client"}
        if len(chunks) >= 9 and chunks[5] in what:
            topic = f" {chunks[9].replace('%', '/')}" if len(chunks) > 9 else ""
            log.info("%s: ROS graph: %s %s%s of node %s %s", self.name, what[chunks[5]],
                     "appeared" if alive else "left", topic, chunks[8], f"({chunks[2]})")

    # -- the frame loop -------------------------------------------------------------

    def _acquire(self) -> None:
        heard, silent_at = False, time.monotonic() + SILENCE_S
        while not self.stopping.is_set():
            if not heard and silent_at and time.monotonic() > silent_at:
                silent_at = 0.0
                why = getattr(self.link, "silence", None)
                if why is not None:
                    log.warning("%s: no JointState after %g s: %s", self.name, SILENCE_S, why())
            try:
                received = self.link.take(0.2)
            except BadInput as exc:
                self.count("bad")
                self.warn("ros_input", f"{self.robot}: refused from {self.config.joint_states}: {exc}")
                continue
            dropped = self.link.queue.dropped
            if dropped > self._dropped:
                self.warn("flood", f"{self.robot}: JointStates arrive faster than they are published: "
                          f"{dropped - self._dropped} dropped (oldest first)")
                self._dropped = dropped
            if received is not None:
                if not heard:
                    heard = True
                    log.info("%s: first JointState from %s: %d joints", self.name, self.link.where,
                             len(received.state.names))
                self.count("received")
                self.count("joint_states")  # (received also counts the bus's commands)
                self._frame(received)

    def _frame(self, received: Received) -> None:
        state = received.state
        if received.lost:
            self.count("ros_lost", received.lost)
        problem = _shape(state)
        if problem:
            self.count("bad")
            self.warn("ros_input", f"{self.robot}: refused from {self.config.joint_states}: {problem}")
            return
        values: dict[str, float] = {}
        for name, position in zip(state.names, state.position, strict=True):
            if self.model.has_joint(name):
                values[name] = wrap(position) if name in self.description.continuous else position
            else:
                self._unknown_joint(name)
        outside = _outside(self.model, values)
        if outside:  # a robot does not report what it cannot reach: a broken driver, or someone else's
            self.count("bad")
            self.warn("ros_input", f"{self.robot}: refused from {self.config.joint_states}: {outside}")
            return
        for joint, mimic in self.description.mimics.items():
            if joint not in values and mimic.joint in values:
                values[joint] = mimic.multiplier * values[mimic.joint] + mimic.offset
        if not values:
            return
        self._seq += 1
        self.publish_frame(self._stamp(state.stamp), self._seq, list(values.values()), list(values))

    def _stamp(self, stamp: cdr.Stamp) -> float:
        now, t = time.time(), stamp.seconds
        if abs(now - t) <= self.config.max_skew_s:
            return t
        self.count("restamped")
        self.warn("stamp", f"{self.robot}: header stamp {t:.3f} is {t - now:+.1f} s from this machine's clock "
                  "(unset, sim time, or clocks apart): frames stamped on receipt instead")
        return now

    def _unknown_joint(self, name: str) -> None:
        self.count("unknown_joints")
        if name not in self._unknown and len(self._unknown) < MAX_NAMED:
            self._unknown.add(name)
            log.warning("%s: joint %r of %s is not in the URDF: left out of the frames", self.name, name[:80],
                        self.config.joint_states)


def _matched() -> str:
    """A link that cannot tell whether the controller is matched: it is taken as matched."""
    return ""


def _outside(model: Any, values: dict[str, float]) -> str:
    """The first heard position outside its URDF limits, or '' (a NaN, "not measured", is left out
    of the frame downstream)."""
    for name, value in values.items():
        spec = model.joint(name)
        if math.isfinite(value) and not spec.min - LIMIT_SLACK <= value <= spec.max + LIMIT_SLACK:
            return f"{name} at {value!r}, outside its URDF limits [{spec.min:g}, {spec.max:g}]"
    return ""


def _shape(state: cdr.JointState) -> str:
    """What is wrong with a JointState's arrays, or ''."""
    n = len(state.names)
    if len(state.position) != n:
        return f"{n} names but {len(state.position)} positions"
    for field, values in (("velocities", state.velocity), ("efforts", state.effort)):
        if values and len(values) != n:
            return f"{n} names but {len(values)} {field}"
    if len(set(state.names)) != n:
        return "a joint is named twice"
    return ""

