"""Bad input from the ROS side, one test per family: each is refused or left out in one
clear line, counted, moves nothing, and the robot's good data goes on."""

from __future__ import annotations

import logging
import math

import pytest

from sonibus.adapters.ros2 import Ros2Config, Ros2Robot
from sonibus.bus import ConfigError, keys

from ..conftest import wait_for
from .conftest import ARM_URDF, ros_attachment, ros_joint_state, start_arm

POSE = {"shoulder": 0.3, "elbow": -0.4}


def _frames(net):
    _, queue = net.bus("watcher").subscribe(keys.frame("arm"))
    return queue


def _goes_on(robot, frames) -> dict:
    """The good data after the bad: a frame of POSE arrives."""
    from sonibus.bus import decode

    def frame():
        robot.publish(POSE)
        item = frames.get(timeout=0.05)
        return decode(item[1]) if item else None
    return wait_for(frame, 5, "a good frame after the bad input")


@pytest.mark.parametrize("payload, attachment, reason", [
    (b"\x00\x01\x00\x00\x01\x00", "good", "more bytes needed"),                      # malformed CDR: cut short
    (b"\x00\x07\x00\x00" + bytes(40), "good", "not plain CDR"),                    # another encapsulation
    ("state", None, "no attachment"),                                               # rmw_zenoh drops these too
    ("state", b"\x01\x02", "an attachment of 2 bytes"),
    ("names-vs-positions", "good", "3 names but 2 positions"),                      # arrays disagree
    ("velocities", "good", "2 names but 1 velocities"),
], ids=["cdr-cut", "cdr-encapsulation", "no-attachment", "short-attachment", "lengths", "velocities"])
def test_a_malformed_joint_state_is_refused_in_one_line_and_the_next_goes_on(net, ros, caplog, payload, attachment,
                                                                               reason):
    robot = ros.robot()
    arm = start_arm(net)
    frames = _frames(net)
    _goes_on(robot, frames)
    payload = {"state": ros_joint_state(POSE),
               "names-vs-positions": ros_joint_state({"shoulder": 0.1, "elbow": 0.2}, names=["shoulder", "elbow", "x"]),
               "velocities": ros_joint_state(POSE, velocity=[1.0])}.get(payload, payload)
    with caplog.at_level(logging.WARNING):
        robot.put(payload, ros_attachment(99, robot.gid) if attachment == "good" else attachment)
        lines = wait_for(lambda: [r.getMessage() for r in caplog.records if "refused from /joint_states"
                                  in r.getMessage()], 5, "the JointState refused")
    assert arm.stats["bad"] == 1
    assert len(lines) == 1 and reason in lines[0], lines
    assert "\n" not in lines[0]
    assert arm.state == "running"
    assert _goes_on(robot, frames)["v"] == [0.3, -0.4]


def test_nan_positions_leave_that_joint_out_and_the_others_go_on(net, ros):
    robot = ros.robot()
    arm = start_arm(net)
    frames = _frames(net)
    from sonibus.bus import decode

    def frame():
        robot.publish({"shoulder": math.nan, "elbow": -0.4, "wrist": math.inf})
        item = frames.get(timeout=0.05)
        return decode(item[1]) if item else None
    message = wait_for(frame, 5, "a frame")
    assert message["names"] == ["elbow"] and message["v"] == [-0.4]
    assert arm.stats["joints_left_out"] >= 2


def test_joints_absent_from_the_urdf_are_left_out_counted_and_named_once(net, ros, caplog):
    robot = ros.robot()
    arm = start_arm(net)
    frames = _frames(net)
    with caplog.at_level(logging.WARNING):
        for _ in range(3):
            robot.publish({**POSE, "gripper_joint": 0.5})
        message = _goes_on(robot, frames)
        wait_for(lambda: arm.stats["unknown_joints"] >= 3, 5, "unknown joints counted")
    assert message["names"] == ["shoulder", "elbow"]
    named = [r.getMessage() for r in caplog.records if "gripper_joint" in r.getMessage()]
    assert len(named) == 1 and "not in the URDF" in named[0], named


def test_a_flood_is_dropped_oldest_first_counted_and_the_node_stays_up(net, ros, caplog):
    robot = ros.robot()
    arm = start_arm(net, queue=16)
    frames = _frames(net)
    _goes_on(robot, frames)
    payload = ros_joint_state(POSE)
    with caplog.at_level(logging.WARNING):
        for seq in range(20_000):
            robot.put(payload, ros_attachment(seq + 1000, robot.gid))
        wait_for(lambda: arm.stats["dropped"] > 0, 10, "the flood dropped")
    assert arm.state == "running"
    assert any("arrive faster than they are published" in r.getMessage() for r in caplog.records)
    _goes_on(robot, frames)


def test_a_urdf_that_does_not_parse_stops_the_start_in_one_line(net, tmp_path):
    broken = tmp_path / "broken.urdf"
    broken.write_text(ARM_URDF.read_text().replace('<limit lower="-1.7"', '<limit lower="a lot"'))
    adapter = Ros2Robot(Ros2Config(robot="arm", urdf=str(broken)), name="arm")
    with pytest.raises(ConfigError) as failed:
        adapter.start(net.bus("arm"))
    message = str(failed.value)
    assert "broken.urdf" in message and "joint 'shoulder'" in message and "'a lot' is not 1 numbers" in message
    assert "\n" not in message and adapter.state == "stopped"
    assert not net.bus("asker").alive(keys.robot_token("arm"))  # no claim is left behind


def test_header_stamps_far_from_this_clock_are_restamped_on_receipt(net, ros):
    robot = ros.robot()
    arm = start_arm(net)
    frames = _frames(net)
    from sonibus.bus import decode

    def frame():
        robot.publish(POSE, stamp=12.5)  # sim time: seconds since the simulation started
        item = frames.get(timeout=0.05)
        return decode(item[1]) if item else None
    message = wait_for(frame, 5, "a frame")
    assert message["t"] > 1e9 and arm.stats["restamped"] >= 1
