"""Fixtures of the ros2 tests: a ROS 2 robot on rmw_zenoh built from the documented wire
format with another implementation than ours (rosbags encodes, zenoh-ext's serializer
attaches, keys and tokens written out here), and the ``ros2`` adapter under test.

    def test_x(net, ros):
        robot = ros.robot()             # a JointState publisher + a trajectory listener, as a ROS 2 arm
        arm = start_arm(net)            # the ros2 adapter, owning robot 'arm'
        robot.publish({"shoulder": 0.5})
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh
from rosbags.typesys import Stores, get_typestore
from zenoh.ext import Int64, z_serialize

from sonibus.adapters.ros2 import Ros2Config, Ros2Robot
from sonibus.bus import keys
from sonibus.bus.node import Bus

from ..conftest import Network, wait_for
from ..web.conftest import websocket  # noqa: F401  (the page's WebSocket client, a fixture here too)

ROOT = Path(__file__).resolve().parent.parent.parent
ARM_URDF = ROOT / "examples" / "ros2-arm.urdf"
CHAINS = {"tool": "tool0", "finger": "finger_left_link", "camera": "camera_link"}
TYPES = get_typestore(Stores.ROS2_JAZZY)
JOINT_STATE, TRAJECTORY = "sensor_msgs/msg/JointState", "trajectory_msgs/msg/JointTrajectory"
STATE_HASH = TYPES.hash_rihs01(JOINT_STATE)
TRAJECTORY_HASH = TYPES.hash_rihs01(TRAJECTORY)
DOMAIN = 0


def ros_joint_state(positions: dict[str, float], stamp: float | None = None, velocity: list[float] | None = None,
                    names: list[str] | None = None) -> bytes:
    """A JointState as rosbags serializes it."""
    t = time.time() if stamp is None else stamp
    sec = int(t)
    header = TYPES.types["std_msgs/msg/Header"](
        stamp=TYPES.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((t - sec) * 1e9)), frame_id="")
    message = TYPES.types[JOINT_STATE](
        header=header, name=names if names is not None else list(positions),
        position=np.array(list(positions.values()), dtype=np.float64),
        velocity=np.array(velocity or [], dtype=np.float64), effort=np.array([], dtype=np.float64))
    return bytes(TYPES.serialize_cdr(message, JOINT_STATE))


def ros_attachment(seq: int, gid: bytes) -> bytes:
    """rmw_zenoh's attachment as zenoh-ext serializes (int64, int64, bytes): not our struct.pack."""
    return z_serialize((Int64(seq), Int64(time.time_ns()), gid)).to_bytes()


class RosArm:
    """A ROS 2 arm as rmw_zenoh puts it on Zenoh: a node token, a JointState publisher (``MP``)
    and a trajectory subscription (``MS``) with their tokens; trajectories kept as rosbags decodes them."""

    def __init__(self, session: zenoh.Session, controller: str, trajectory_hash: str = TRAJECTORY_HASH,
                 controller_node: str = "") -> None:
        zid = str(session.zid())
        node = f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%/fake_arm"
        publisher = f"@ros2_lv/{DOMAIN}/{zid}/0/1/MP/%/%/fake_arm/%joint_states/" \
                    f"sensor_msgs::msg::dds_::JointState_/{STATE_HASH}/::,10:,:,:,,"
        # the controller is a node of its own, named after the topic's parent (JTC's ``~/joint_trajectory``)
        name = controller_node or controller.strip("/").split("/")[-2]
        jtc = f"@ros2_lv/{DOMAIN}/{zid}/1/1/NN/%/%/{name}"
        subscription = f"@ros2_lv/{DOMAIN}/{zid}/1/2/MS/%/%/{name}/{controller.replace('/', '%')}/" \
                       f"trajectory_msgs::msg::dds_::JointTrajectory_/{trajectory_hash}/::,10:,:,:,,"
        self.tokens = [session.liveliness().declare_token(key) for key in (node, publisher, jtc, subscription)]
        self.publisher = session.declare_publisher(f"{DOMAIN}/joint_states/sensor_msgs::msg::dds_::JointState_/"
                                                   f"{STATE_HASH}")
        self.gid, self.seq = bytes(range(16)), 0
        self.trajectories: list[Any] = []
        self.attachments: list[bytes | None] = []
        key = f"{DOMAIN}/{controller.strip('/')}/trajectory_msgs::msg::dds_::JointTrajectory_/{trajectory_hash}"
        self.subscriber = session.declare_subscriber(key, self._trajectory)

    def _trajectory(self, sample: zenoh.Sample) -> None:
        self.attachments.append(sample.attachment.to_bytes() if sample.attachment is not None else None)
        self.trajectories.append(TYPES.deserialize_cdr(sample.payload.to_bytes(), TRAJECTORY))

    def publish(self, positions: dict[str, float], **options: Any) -> None:
        self.seq += 1
        self.put(ros_joint_state(positions, **options), ros_attachment(self.seq, self.gid))

    def put(self, payload: bytes, attachment: bytes | None) -> None:
        self.publisher.put(payload, attachment=attachment)

    def close(self) -> None:
        for entity in [self.subscriber, self.publisher, *self.tokens]:
            entity.undeclare()


class Ros:
    """Makes ``RosArm`` s on the test's network (each on a session of its own: another machine)."""

    def __init__(self, net: Network) -> None:
        self.net, self.arms = net, []

    def robot(self, controller: str = "/joint_trajectory_controller/joint_trajectory", **options: Any) -> RosArm:
        bus: Bus = self.net.bus("ros")
        arm = RosArm(bus.session, controller, **options)
        self.arms.append(arm)
        return arm

    def close(self) -> None:
        for arm in self.arms:
            arm.close()


@pytest.fixture
def ros(net: Network) -> Iterator[Ros]:
    made = Ros(net)
    try:
        yield made
    finally:
        made.close()


def seeing(net: Network, name: str, robot: str = "arm") -> Bus:
    """A session of its own (another machine) once it sees ``robot``'s info: a new session
    reaches the others a moment after it opens, and a command sent before is 'not found'."""
    bus = net.bus(name)
    wait_for(lambda: bus.query(keys.info(robot), timeout=1.0), 10, f"robot '{robot}' seen from session '{name}'")
    return bus


def start_arm(net: Network, **options: Any) -> Ros2Robot:
    """The ros2 adapter owning robot ``arm`` from examples/ros2-arm.urdf (``options``: Ros2Config's)."""
    config = Ros2Config(**{"robot": "arm", "urdf": str(ARM_URDF), "chains": CHAINS, **options})
    return net.start(Ros2Robot(config, name="arm"))
