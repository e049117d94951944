"""A ROS 2 robot over rmw_zenoh, played by a publisher built from the documented wire format
with rosbags (conftest.RosArm), drives the sinks as any robot does; commands from the page
reach it as JointTrajectory that rosbags decodes; stop works with the ROS side gone."""

from __future__ import annotations

import math
import socket

import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.recorder.reading import Recording
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.adapters.ros2 import rmw
from sonibus.bus import keys
from sonibus.bus.client import send_command
from sonibus.bus.errors import CommandError

from ..conftest import wait_for
from ..web.conftest import start_web
from .conftest import TRAJECTORY_HASH, seeing, start_arm

POSE = {"lift": 0.1, "torso_yaw": 0.2, "shoulder": 0.3, "elbow": -0.4, "wrist": 0.5, "finger_left": 0.02,
        "head_pan": 0.1}


def _frames(net, robot="arm"):
    bus = net.bus("watcher")
    _, queue = bus.subscribe(keys.frame(robot))
    return bus, queue


def test_joint_states_drive_osc_recorder_and_page_and_the_page_moves_the_robot(net, ros, tmp_path, websocket):
    robot = ros.robot()
    arm = start_arm(net)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    udp.settimeout(0.2)
    net.start(OscSink(OscSinkConfig(subscribe=("arm/joints/*",), targets=(f"127.0.0.1:{udp.getsockname()[1]}",),
                                max_age_ms=5000), name="sound"))
    recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "arm.mcap"), subscribe=("arm/**",)),
                                  name="recorder"))
    web = start_web(net)
    page = websocket(web.url.replace("http://", "ws://") + "/ws")
    page.wait("robots", timeout=10)
    heard: dict[str, float] = {}

    def osc() -> bool:
        robot.publish(POSE)
        try:
            message = OscMessage(udp.recv(1024))
            heard[message.address] = message.params[0]
        except TimeoutError:
            pass
        return "/arm/joints/shoulder" in heard and "/arm/joints/finger_right" in heard

    wait_for(osc, 10, "OSC of the ROS joints")
    assert heard["/arm/joints/shoulder"] == pytest.approx(0.3, abs=1e-6)
    assert heard["/arm/joints/finger_right"] == pytest.approx(-0.02, abs=1e-6)  # a mimic joint, filled in
    frame = page.wait("frame", robot="arm")
    assert dict(zip(frame["names"], frame["v"], strict=True))["elbow"] == pytest.approx(-0.4)

    page.send({"type": "command", "id": 1, "robot": "arm", "verb": "joints/set",
               "args": {"names": ["shoulder"], "angles": [1.0], "speed": 0.5}})
    reply = page.wait("reply", id=1)
    assert reply["ok"], reply
    wait_for(lambda: robot.trajectories, 5, "a JointTrajectory at the ROS robot")
    trajectory = robot.trajectories[-1]
    assert rmw.read_attachment(robot.attachments[-1]).sequence >= 1  # as rmw_zenoh attaches it
    assert list(trajectory.joint_names) == ["shoulder"]  # the joints it does not name are not moved
    point = trajectory.points[0]
    assert list(point.positions) == [1.0]
    # from the furthest the shoulder could be (its lower limit, -1.7: heard positions do not count) at half speed
    shoulder = arm.model.joint("shoulder")
    assert point.time_from_start.sec + point.time_from_start.nanosec * 1e-9 == pytest.approx(
        (1.0 - shoulder.min) / (0.5 * shoulder.max_velocity), abs=1e-3)

    recorder.stop()
    with Recording(str(tmp_path / "arm.mcap")) as recording:
        recorded = [m.data for m in recording.messages(["arm/frame"])]
    assert recorded and "shoulder" in recorded[0]["names"]


def test_robot_info_carries_the_urdf_joint_table_and_chains(net, ros):
    start_arm(net, postures={"home": {"shoulder": 0.5}})
    info = seeing(net, "asker").query(keys.info("arm"))[0]
    joints = {j["name"]: j for j in info["joints"]}
    assert joints["lift"]["unit"] == "m" and joints["lift"]["max"] == 0.3 and joints["lift"]["max_velocity"] == 0.1
    assert joints["torso_yaw"]["min"] == -math.pi and joints["torso_yaw"]["max"] == math.pi   # continuous
    assert joints["finger_right"]["chain"] == "finger"       # a mimic joint goes with its source
    assert set(info["kinematics"]["chains"]) == {"tool", "finger", "camera"}
    assert info["kinematics"]["chains"]["tool"][-1]["joint"] == "tool0"
    assert info["postures"] == ["home"]


def test_unsupported_verbs_are_refused_with_their_own_code_and_limits_hold(net, ros):
    robot = ros.robot()
    start_arm(net)
    bus = seeing(net, "sender")
    for verb, args in (("say", {"text": "hello"}), ("behavior/run", {"name": "wave"}),
                       ("stiffness", {"names": ["Body"], "value": 1.0}), ("awareness", {"enabled": True})):
        with pytest.raises(CommandError) as refused:
            send_command(bus, "arm", verb, args)
        assert refused.value.code == "unsupported" and "ROS 2 robot" in refused.value.message
    _, frames = _frames(net)
    wait_for(lambda: robot.publish(POSE) or frames.get(timeout=0.05), 5, "the arm's positions heard")
    for args, code in (({"names": ["shoulder"], "angles": [2.0]}, "out_of_range"),
                       ({"names": ["finger_right"], "angles": [-0.01]}, "bad_request"),  # mimic: set its source
                       ({"names": ["gripper"], "angles": [0.0]}, "unknown_joint")):
        with pytest.raises(CommandError) as refused:
            send_command(bus, "arm", "joints/set", args)
        assert refused.value.code == code, refused.value.message
    assert not robot.trajectories  # nothing refused moved the robot


def test_stop_is_the_controllers_hold_and_says_when_it_reached_no_controller(net, ros):
    robot = ros.robot()
    arm = start_arm(net)
    bus = seeing(net, "sender")
    wait_for(lambda: not arm.link.matched(), 5, "the controller's subscription matched")
    assert send_command(bus, "arm", "stop", {}) == {"hold_sent": True}  # no joint state heard: it needs none
    wait_for(lambda: robot.trajectories, 5, "the hold trajectory")
    hold = robot.trajectories[-1]
    # joint_trajectory_controller's own stop-and-hold: every joint named, no point (nothing to move to)
    assert list(hold.joint_names) == ["lift", "torso_yaw", "shoulder", "elbow", "wrist", "finger_left", "head_pan"]
    assert list(hold.points) == [] and (hold.header.stamp.sec, hold.header.stamp.nanosec) == (0, 0)
    robot.close()
    ros.arms.remove(robot)  # the ROS side is gone: stop says it reached nothing
    wait_for(lambda: arm.link.matched(), 5, "the controller's subscription gone")
    answer = send_command(bus, "arm", "stop", {})
    assert answer["reached"] is False and "reached no controller" in answer["error"], answer
    assert "no subscription of node joint_trajectory_controller" in answer["error"], answer
    with pytest.raises(CommandError) as refused:
        send_command(bus, "arm", "joints/set", {"names": ["shoulder"], "angles": [0.5]})
    assert refused.value.code == "not_connected", refused.value.message


def test_the_graph_sees_our_tokens_and_we_follow_the_controllers_type_hash(net, ros):
    humble = ros.robot(trajectory_hash="TypeHashNotSupported")  # a Humble-era controller
    arm = start_arm(net)
    bus = seeing(net, "graph")
    ours: list[str] = []

    def seen() -> bool:  # (a session just opened reaches the arm's a moment later: waited for, not assumed)
        ours[:] = [t for t in bus.alive("@ros2_lv/0/**") if f"/{arm.link.bus.zid}/" in t]
        return (any(t.endswith("/NN/%/%/sonibus") for t in ours) and
                any("/MS/%/%/sonibus/%joint_states/sensor_msgs::msg::dds_::JointState_/" in t for t in ours))

    wait_for(seen, 10, "our node and subscription tokens in the graph", lambda: f"tokens: {ours}")
    wait_for(lambda: arm.link.trajectory_hash == "TypeHashNotSupported" or
             (humble.publish(POSE) and False), 5, "the controller's type hash adopted")
    assert any("/MP/%/%/sonibus/%joint_trajectory_controller%joint_trajectory/trajectory_msgs::msg::dds_::"
               "JointTrajectory_/TypeHashNotSupported/" in t for t in bus.alive("@ros2_lv/0/**")), ours
    _, frames = _frames(net)
    wait_for(lambda: humble.publish(POSE) or frames.get(timeout=0.05), 5, "positions heard")
    send_command(bus, "arm", "stop", {})
    wait_for(lambda: humble.trajectories, 5, "a trajectory on the Humble key")
    assert TRAJECTORY_HASH not in arm.link.trajectory_key
