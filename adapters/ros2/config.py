"""Options of the ``ros2`` adapter: which middleware, where the robot's topics are, where
its description comes from, and what sonibus may command."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

from sonibus.bus import keys
from sonibus.bus.busconfig import PROTOCOLS
from sonibus.bus.options import bad

MIDDLEWARES = ("zenoh", "dds")


def _topic(key: str, value: str) -> None:
    if not value.strip("/") or any(c in value for c in " *$?#@%") or "//" in value:
        raise bad(key, f"'{value}' is not a ROS topic name (e.g. /joint_states)")


@dataclass(frozen=True)
class Ros2Config:
    """Options of the ``ros2`` adapter (docs/ros2.md has every key with an example)."""

    robot: str = "arm"                       # bus name of the robot
    middleware: Literal["zenoh", "dds"] = "zenoh"  # rmw_zenoh, or a DDS (Fast DDS, Cyclone DDS, Connext)
    domain_id: int = 0                       # ROS_DOMAIN_ID
    joint_states: str = "/joint_states"      # the sensor_msgs/JointState topic
    controller: str = "/joint_trajectory_controller/joint_trajectory"  # trajectory_msgs/JointTrajectory in
    joints: tuple[str, ...] = ()             # the controller's joints (default: every movable, non-mimic one)
    urdf: str = ""                           # a URDF file; "topic": the robot's /robot_description
    description_topic: str = "/robot_description"
    description_timeout_s: float = 10.0      # how long to wait for /robot_description
    srdf: str = ""                           # an SRDF file: its group states become postures
    postures: dict[str, Any] = field(default_factory=dict)  # name → {joint: position}
    chains: dict[str, Any] = field(default_factory=dict)    # name → tip link: hand/end-effector points
    chain_root: str = ""                     # the link chains start from (default: the URDF's root)
    default_velocity: float = 1.0            # rad/s or m/s where the URDF gives no velocity limit
    rate_hz: float = 100.0                   # how often the robot publishes its joint states (info)
    stop_s: float = 0.2                      # unused: stop is the controller's own hold (kept: older files load)
    max_skew_s: float = 2.0                  # header stamps further from this clock: frames stamped on receipt
    queue: int = 256                         # JointStates waiting to be published; the oldest go first
    # rmw_zenoh: the sonibus bus's own Zenoh network, or a router of the ROS side
    router: str = ""                         # e.g. tcp/127.0.0.1:7447 (rmw_zenohd's default)
    node_name: str = "sonibus"               # our ROS node's name in the graph
    # DDS (Cyclone DDS, the `ros2-dds` extra)
    interface: str = ""                      # network interface (e.g. eth0, lo); "" Cyclone's choice
    peers: tuple[str, ...] = ()              # unicast peers (addresses) where multicast does not reach
    multicast: bool = True

    def __post_init__(self) -> None:
        keys.check_name("robot", self.robot)
        if not 0 <= self.domain_id <= 232:
            raise bad("domain_id", f"{self.domain_id} must be in 0..232 (ROS_DOMAIN_ID)")
        for key in ("joint_states", "controller", "description_topic"):
            _topic(key, getattr(self, key))
        if not self.urdf:
            raise bad("urdf", "is needed: a URDF file, or \"topic\" for the robot's /robot_description")
        if self.router and self.router.partition("/")[0] not in PROTOCOLS:
            raise bad("router", f"'{self.router}' is not a Zenoh endpoint (e.g. tcp/127.0.0.1:7447)")
        if self.router and self.middleware != "zenoh":
            raise bad("router", "is for middleware = \"zenoh\"")
        for key, value, low, high in (("rate_hz", self.rate_hz, 0, 1000), ("stop_s", self.stop_s, 0, 5),
                                      ("max_skew_s", self.max_skew_s, 0, 3600),
                                      ("default_velocity", self.default_velocity, 0, 1000),
                                      ("description_timeout_s", self.description_timeout_s, 0, 300)):
            if not (math.isfinite(value) and low < value <= high):
                raise bad(key, f"{value:g} must be in ({low}, {high}]")
        if not 1 <= self.queue <= 100_000:
            raise bad("queue", f"{self.queue} must be in 1..100000")
        for name, tip in self.chains.items():
            keys.check_name("chain", name)
            if not isinstance(tip, str) or not tip:
                raise bad("chains", f"chain '{name}': {tip!r} is not a link name")
        for name, values in self.postures.items():
            if not isinstance(values, dict) or not values:
                raise bad("postures", f"posture '{name}': {values!r} is not a table of joint = position")
        if not self.node_name.replace("_", "a").isalnum():
            raise bad("node_name", f"'{self.node_name}' is not a ROS node name (letters, digits, _)")
