"""STOP never lies and never moves a robot (issue 33): a rogue node's subscription on the
controller's topic neither takes the trajectories nor makes a stop say it held; joint states
heard from ROS (anyone on the graph can publish them) never become a target nor shorten a move;
``stop`` is joint_trajectory_controller's own hold. The trajectories are checked against the URDF
as yourdfpy reads it, not as the adapter does."""

from __future__ import annotations

import logging
import math

import yourdfpy
import zenoh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sonibus.adapters.ros2 import rmw
from sonibus.adapters.ros2.sim import SimArm, SimArmConfig
from sonibus.bus import keys
from sonibus.bus.client import send_command

from ..conftest import wait_for
from .conftest import ARM_URDF, DOMAIN, TRAJECTORY_HASH, seeing, start_arm

CONTROLLER = "/joint_trajectory_controller/joint_trajectory"
ROGUE_HASH = "RIHS01_" + "f" * 64
REFERENCE = yourdfpy.URDF.load(str(ARM_URDF), build_scene_graph=False, load_meshes=False)
COMMANDED = ["lift", "torso_yaw", "shoulder", "elbow", "wrist", "finger_left", "head_pan"]  # finger_right mimics


def _rogue(session: zenoh.Session, node: str, node_id: int) -> list:
    """A node whose liveliness tokens declare a subscription to the controller's topic with a made-up hash."""
    zid = str(session.zid())
    keys_ = (f"@ros2_lv/{DOMAIN}/{zid}/{node_id}/{node_id}/NN/%/%/{node}",
             f"@ros2_lv/{DOMAIN}/{zid}/{node_id}/7/MS/%/%/{node}/{CONTROLLER.replace('/', '%')}/"
             f"trajectory_msgs::msg::dds_::JointTrajectory_/{ROGUE_HASH}/::,10:,:,:,,")
    return [session.liveliness().declare_token(key) for key in keys_]


def _stops(bus, robot, count: int) -> None:
    """``count`` stops, each answered hold_sent and each received by the controller on its key."""
    before = len(robot.trajectories)
    for i in range(count):
        assert send_command(bus, "arm", "stop", {}) == {"hold_sent": True}
        wait_for(lambda i=i: len(robot.trajectories) >= before + i + 1, 5, f"stop {i + 1} at the controller")


def test_a_rogue_subscription_takes_no_trajectory_and_no_stop_lies(net, ros, caplog):
    robot = ros.robot()
    arm = start_arm(net)
    bus = seeing(net, "sender")
    wait_for(lambda: not arm.link.matched(), 5, "the controller's subscription matched")
    rogue_bus = net.bus("rogue")
    with caplog.at_level(logging.INFO, "sonibus"):  # (an earlier test in this worker may have set its level)
        # one rogue under a name of its own, one that says it is the controller's node
        rogues = _rogue(rogue_bus.session, "rogue", 5) + _rogue(rogue_bus.session, "joint_trajectory_controller", 6)
        wait_for(lambda: sum("subscription appeared /joint_trajectory_controller/joint_trajectory of node "
                             in r.getMessage() and rogue_bus.zid in r.getMessage() for r in caplog.records) >= 2,
                 10, "both rogue subscriptions seen")
        _stops(bus, robot, 5)  # every stop reaches the controller on the real key
        assert arm.link.trajectory_hash == TRAJECTORY_HASH
        for token in rogues:
            token.undeclare()
        wait_for(lambda: sum("subscription left" in r.getMessage() and rogue_bus.zid in r.getMessage()
                             for r in caplog.records) >= 2, 5, "the rogues gone")
    _stops(bus, robot, 5)  # and after it left
    assert arm.link.trajectory_hash == TRAJECTORY_HASH
    assert all(rmw.read_attachment(a).sequence >= 1 for a in robot.attachments)
    robot.close()
    ros.arms.remove(robot)
    rogues = _rogue(rogue_bus.session, "rogue", 5)  # only a rogue left: a stop reaches no controller
    wait_for(lambda: arm.link.matched(), 5, "the controller gone")
    answer = send_command(bus, "arm", "stop", {})
    assert answer["reached"] is False and "reached no controller" in answer["error"], answer
    info = bus.query(keys.info("arm"), timeout=2.0)
    assert info and info[0]["controller"]["matched"] is False and "no subscription" in info[0]["controller"]["why"]
    assert arm.describe()["controller"]["matched"] is False  # what `sonibus nodes` shows
    for token in rogues:
        token.undeclare()


def test_joint_states_outside_the_urdf_limits_are_bad_input(net, ros):
    robot = ros.robot()
    arm = start_arm(net)
    _, frames = net.bus("watcher").subscribe(keys.frame("arm"))
    for fake in ({"shoulder": 100.0}, {"lift": 7.0}, {"wrist": 1e6}, {"head_pan": -2.0}):
        bad = arm.stats.get("bad", 0)
        robot.publish({"elbow": -0.4, **fake})
        wait_for(lambda b=bad: arm.stats.get("bad", 0) > b, 5, f"{fake} refused")
    assert frames.get(timeout=0.2) is None  # none of them became a frame
    wait_for(lambda: robot.publish({"shoulder": 1.7, "elbow": -0.4}) or frames.get(timeout=0.05), 5,
             "a JointState within the limits (at one) goes on")


def _limits(name: str) -> tuple[float, float, float, bool]:
    joint = REFERENCE.joint_map[name]
    continuous = joint.type == "continuous"
    low, high = (-math.pi, math.pi) if continuous else (joint.limit.lower, joint.limit.upper)
    return low, high, joint.limit.velocity, continuous


def _check(trajectory, command: dict) -> None:
    """What a trajectory may be: stop names every controller joint and moves none (no point); a
    joints/set names only its joints, within their limits, reached no faster than their URDF velocity
    from anywhere within their limits (a continuous joint: half a turn, the controller's wraparound)."""
    names = list(trajectory.joint_names)
    if command["verb"] == "stop":
        assert names == COMMANDED and list(trajectory.points) == []
        return
    assert names == command["names"] and len(trajectory.points) == 1
    point = trajectory.points[0]
    seconds = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
    for name, value in zip(names, point.positions, strict=True):
        low, high, velocity, continuous = _limits(name)
        assert low <= value <= high, (name, value)
        furthest = math.pi if continuous else max(value - low, high - value)
        assert furthest / seconds <= velocity * (1 + 1e-6), (name, value, seconds, velocity)


def _heard():
    """A JointState anyone could publish: in or far out of the limits, some joints or all."""
    value = st.one_of(st.floats(-2.0, 2.0), st.floats(-1e6, 1e6), st.sampled_from([100.0, 7.0, 1e6, -50.0]))
    return st.dictionaries(st.sampled_from(COMMANDED), value, min_size=1)


def _command():
    def joints(names):
        return st.tuples(*(st.floats(*_limits(n)[:2]) for n in names)).map(
            lambda angles: {"verb": "joints/set", "names": names, "angles": list(angles)})
    move = st.lists(st.sampled_from(COMMANDED), min_size=1, max_size=3, unique=True).flatmap(joints)
    speed = st.floats(0.05, 1.0)
    return st.one_of(st.just({"verb": "stop"}), st.tuples(move, speed).map(lambda m: {**m[0], "speed": m[1]}))


def test_no_heard_state_becomes_a_target_or_a_speed_past_the_urdfs(net, ros):
    robot = ros.robot()
    arm = start_arm(net)
    bus = seeing(net, "sender")
    wait_for(lambda: not arm.link.matched(), 5, "the controller's subscription matched")

    @settings(max_examples=30, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
    @given(heard=_heard(), command=_command())
    def property_(heard, command):
        taken = arm.stats.get("received", 0)
        robot.publish(heard)
        wait_for(lambda: arm.stats.get("received", 0) > taken, 5, "the heard state taken")
        before = len(robot.trajectories)
        args = {k: v for k, v in command.items() if k != "verb"}
        send_command(bus, "arm", command["verb"], args)
        wait_for(lambda: len(robot.trajectories) > before, 5, "the trajectory at the controller")
        _check(robot.trajectories[-1], command)

    property_()


def test_the_stand_in_arm_is_not_moved_by_stop_or_by_joints_a_command_does_not_name(net, ros):
    sim = net.start(SimArm(SimArmConfig(urdf=str(ARM_URDF), idle=False, rate_hz=50.0), name="arm-sim"))
    arm = start_arm(net)
    bus = seeing(net, "sender")
    wait_for(lambda: not arm.link.matched(), 5, "the stand-in's controller matched")
    spoofer = ros.robot(controller="/elsewhere/joint_trajectory")  # another JointState publisher
    before = dict(sim.position)
    for _ in range(5):
        spoofer.publish({"shoulder": 1.6, "elbow": -2.0, "lift": 0.0, "head_pan": 1.5})  # fakes within the limits
    assert send_command(bus, "arm", "stop", {}) == {"hold_sent": True}
    wait_for(lambda: sim.stats.get("trajectories", 0) >= 1, 5, "the stop at the stand-in")
    send_command(bus, "arm", "joints/set", {"names": ["head_pan"], "angles": [0.2], "speed": 1.0})
    wait_for(lambda: sim.stats.get("trajectories", 0) >= 2, 5, "the head move at the stand-in")
    wait_for(lambda: abs(sim.position["head_pan"] - 0.2) < 1e-9, 10, "the head where it was sent")
    assert {n: v for n, v in sim.position.items() if n != "head_pan"} == \
        {n: v for n, v in before.items() if n != "head_pan"}  # nothing else moved, spoofed states or not


def test_the_page_and_nodes_say_whether_the_controller_is_matched(net, ros):
    from sonibus.bus.cli.watch import node_line

    from ..web.conftest import start_web

    web = start_web(net)
    arm = start_arm(net)  # no controller yet
    wait_for(lambda: web.shown_robots().get("arm", {}).get("controller", {}).get("matched") is False, 10,
             "the page showing the controller unmatched")
    assert "no subscription of node joint_trajectory_controller" in web.shown_robots()["arm"]["controller"]["why"]
    assert "CONTROLLER NOT MATCHED: no subscription" in node_line("h", "arm", arm.describe(), 0.0)
    ros.robot()
    wait_for(lambda: web.shown_robots()["arm"]["controller"] == {"matched": True, "why": ""}, 10,
             "the page showing the controller matched")
    assert node_line("h", "arm", arm.describe(), 0.0).endswith("controller matched")


def test_the_stand_in_arm_holds_a_commanded_joint_and_sways_the_others(net):
    """Issue 37, item 1: ros2-sim swayed every joint, a commanded one too (0.8 sent, 0.64-0.97
    read), and nothing said so. A joint a trajectory named holds where it was sent."""
    sim = net.start(SimArm(SimArmConfig(urdf=str(ARM_URDF), idle=True, rate_hz=50.0), name="arm-sim"))
    arm = start_arm(net)
    bus = seeing(net, "sender")
    wait_for(lambda: not arm.link.matched(), 5, "the stand-in's controller matched")
    send_command(bus, "arm", "joints/set", {"names": ["shoulder"], "angles": [0.8], "speed": 1.0})
    wait_for(lambda: abs(sim.shown["shoulder"] - 0.8) < 1e-9, 10, "the shoulder at 0.8")
    shoulder, elbow = [], []
    wait_for(lambda: shoulder.append(sim.shown["shoulder"]) or elbow.append(sim.shown["elbow"]) or len(shoulder) > 100,
             10, "two seconds of the arm")
    assert max(abs(v - 0.8) for v in shoulder) < 1e-9, "the commanded shoulder swayed"
    assert max(elbow) - min(elbow) > 1e-3, "the elbow, never commanded, sways no more: the stand-in is not idle"
