"""``ros2-sim``: a stand-in for a ROS 2 robot, for examples and tests where there is none.

It is not a ROS node: it speaks what a ROS 2 arm under ros2_control puts on the wire
over rmw_zenoh, from the documented format — ``sensor_msgs/JointState`` on
``/joint_states`` with rmw_zenoh's attachment, ``/robot_description`` (its URDF,
from a publisher that keeps it for late subscribers, as transient local does), the
graph's liveliness tokens — and it follows the ``trajectory_msgs/JointTrajectory``
sent to its controller's topic. What a real robot does beyond that (its controller's
checks, its ROS graph, Humble's type hashes) it does not: docs/ros2.md lists what only
a real robot can confirm.

    [nodes.arm-sim]
    adapter = "ros2-sim"
    urdf = "examples/ros2-arm.urdf"
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from sonibus.bus import Adapter, ConfigError
from sonibus.bus.node import Qos
from sonibus.bus.options import bad
from sonibus.bus.pacing import Pacer
from sonibus.bus.queue import SampleQueue

from . import cdr, rmw
from .description import describe
from .urdf import UrdfError, parse
from .zenoh_link import RosSession, controller_node

JOINT_STATES = Qos(drop=True)  # like a sensor stream: never block the robot


@dataclass(frozen=True)
class SimArmConfig:
    """Options of the ``ros2-sim`` adapter."""

    urdf: str = ""                           # the robot's URDF file
    domain_id: int = 0
    joint_states: str = "/joint_states"
    controller: str = "/joint_trajectory_controller/joint_trajectory"
    description_topic: str = "/robot_description"
    rate_hz: float = 100.0
    idle: bool = True                        # sway gently, the joints no trajectory has named yet
    router: str = ""                         # publish through this router instead of the sonibus network
    node_name: str = "sim_arm"

    def __post_init__(self) -> None:
        if not self.urdf:
            raise bad("urdf", "is needed: the simulated robot's URDF file")
        if not 0 < self.rate_hz <= 1000:
            raise bad("rate_hz", f"{self.rate_hz:g} must be in (0, 1000]")


class SimArm(Adapter):
    """A simulated ROS 2 arm on rmw_zenoh's wire format (a stand-in, not a ROS node)."""

    Config = SimArmConfig
    counters = ("trajectories",)

    def _start(self) -> None:
        c = self.config
        try:
            urdf = self.resolve(c.urdf)
            text = Path(urdf).read_text(encoding="utf-8")
            self.description = describe(parse(text, urdf))
        except (OSError, UrdfError) as exc:
            raise ConfigError(f"ros2-sim: {exc}") from None
        model = self.description.model
        self.names = model.joint_names
        self.position = {j.name: j.clamp(0.0) for j in model.joints}
        self.start, self.goal, self.t0, self.t1 = dict(self.position), dict(self.position), 0.0, 0.0
        self.held: set[str] = set()  # joints a trajectory named: they no longer sway
        self.shown = dict(self.position)
        bus = self.own(RosSession(c.router, self.bus)).bus if c.router else self.bus
        node = rmw.Node(c.domain_id, bus.zid, c.node_name)
        self.own(bus.token(node.token()))
        state_hash, trajectory_hash, string_hash = (rmw.HASHES[t] for t in (rmw.JOINT_STATE, rmw.JOINT_TRAJECTORY,
                                                                            rmw.STRING))
        state_token = node.entity(1, "MP", c.joint_states, rmw.JOINT_STATE, state_hash, rmw.QOS_DEPTH_10)
        self.own(bus.token(state_token))
        self.gid, self.seq = rmw.gid(state_token), 0
        self.publisher = self.own(bus.stream_publisher(rmw.topic_key(c.domain_id, c.joint_states, rmw.JOINT_STATE,
                                                                     state_hash), JOINT_STATES, encoding=None))
        # the controller is a node of its own, named after it (JTC subscribes to ``~/joint_trajectory``)
        named = controller_node(c.controller)
        controller = rmw.Node(c.domain_id, bus.zid, named[1] if named else c.node_name, node_id=1)
        if named:
            self.own(bus.token(controller.token()))
        self.own(bus.token(controller.entity(2, "MS", c.controller, rmw.JOINT_TRAJECTORY, trajectory_hash,
                                             rmw.QOS_DEPTH_10)))
        self.commands = self.own(SampleQueue(16))
        self.own(bus.subscribe(rmw.topic_key(c.domain_id, c.controller, rmw.JOINT_TRAJECTORY), queue=self.commands,
                               attachment=True)[0])
        description_token = node.entity(3, "MP", c.description_topic, rmw.STRING, string_hash,
                                        rmw.QOS_TRANSIENT_LOCAL)
        self.own(bus.token(description_token))
        keeper = self.own(bus.stream_publisher(rmw.topic_key(c.domain_id, c.description_topic, rmw.STRING,
                                                             string_hash), Qos(), encoding=None, cache=1))
        keeper.put(cdr.string(text), attachment=rmw.attachment(1, time.time_ns(), rmw.gid(description_token)))
        self.spawn(self._run, "arm")

    def _run(self) -> None:
        Pacer(self.config.rate_hz).run(self._step, self.stopping)

    def _step(self, _seq: int) -> None:
        for item in self.commands.drain(timeout=0):
            self._follow(item)
        now = time.time()
        share = 1.0 if now >= self.t1 else max(0.0, (now - self.t0) / (self.t1 - self.t0))
        for name in self.names:
            self.position[name] = self.start[name] + share * (self.goal[name] - self.start[name])
        shown = dict(self.position)
        if self.config.idle and now >= self.t1:
            gain = min(1.0, (now - self.t1) / 2.0)  # the sway comes back slowly after a move: no jump
            for i, joint in enumerate(self.description.model.joints):
                if self.description.is_commanded(joint.name) and joint.name not in self.held:
                    sway = gain * 0.05 * (joint.max - joint.min) * math.sin(0.5 * now + i)
                    shown[joint.name] = joint.clamp(self.position[joint.name] + sway)
        for joint, mimic in self.description.mimics.items():
            shown[joint] = mimic.multiplier * shown[mimic.joint] + mimic.offset
        self.shown = shown
        self.seq += 1
        payload = cdr.joint_state(cdr.Stamp.of(now), list(shown), list(shown.values()))
        self.publisher.put(payload, attachment=rmw.attachment(self.seq, time.time_ns(), self.gid))
        self.count("sent")

    def _follow(self, item: tuple[str, bytes, bytes | None]) -> None:
        """A trajectory, as joint_trajectory_controller takes it from its topic: no points is its
        stop-and-hold (where the arm is now); otherwise from where the arm is to the last point, in
        that point's time, the joints it does not name held (``allow_partial_joints_goal``). Like the
        controller, it follows whatever it gets at whatever speed it says: limits are the sender's."""
        try:
            rmw.read_attachment(item[2])
            trajectory = cdr.read_joint_trajectory(item[1])
        except ValueError as exc:
            self.count("bad")
            self.warn("trajectory", f"refused a trajectory: {exc}")
            return
        if not trajectory.names or any(n not in self.position for n in trajectory.names):
            self.count("bad")
            self.warn("trajectory", f"refused a trajectory for {', '.join(trajectory.names)}: no joints, or unknown")
            return
        self.count("trajectories")
        # a joint once commanded holds where it is sent (it swayed on: 0.8 sent, 0.64-0.97 read); a stop holds all
        self.held.update(trajectory.names if trajectory.points else self.names)
        self.position.update(self.shown)  # from where it is seen, sway included
        self.start, self.goal = dict(self.position), dict(self.position)
        self.t0 = time.time()
        if not trajectory.points:
            self.t1 = self.t0  # hold here
            return
        last = trajectory.points[-1]
        self.goal.update(zip(trajectory.names, last.positions, strict=True))
        self.t1 = self.t0 + max(last.seconds, 1e-3)
