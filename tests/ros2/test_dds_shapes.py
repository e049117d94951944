"""The ``ros2`` adapter on DDS, configured only as docs/ros2.md says (``interface = "lo"``),
meets a Cyclone DDS robot in ROS 2's localhost mode (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``:
unicast only, no multicast, its peer 127.0.0.1, as rmw_cyclonedds configures it), in a process
of its own; without a robot it says so, and a ``stop`` says it reached no controller."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

from sonibus.bus.client import send_command

from ..conftest import wait_for
from ..net.conftest import _stale_removed, topology  # noqa: F401  (fixtures: a network namespace)
from ..net.netns import NsProcess, ip
from .conftest import ARM_URDF, seeing, start_arm

ROBOT = Path(__file__).with_name("cyclone_robot.py")
PROBE = Path(__file__).with_name("dds_link_probe.py")
# rmw_cyclonedds's configuration in localhost mode (before the user's CYCLONEDDS_URI)
LOCALHOST = ('<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
             "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
             "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
             '<Peers><Peer Address="localhost"/></Peers></Discovery></Domain></CycloneDDS>')


def _domain(offset: int) -> int:
    return 200 + (os.getpid() + offset) % 30  # apart from test_dds_path's (100..199) and other runs


def test_a_cyclone_robot_in_localhost_mode_meets_the_adapter_as_documented(net, spawn):
    domain = _domain(0)
    robot = spawn(sys.executable, str(ROBOT), str(domain), collect=True,
                  env={**os.environ, "CYCLONEDDS_URI": LOCALHOST})
    wait_for(lambda: robot.lines, 10, "the Cyclone robot ready")
    arm = start_arm(net, middleware="dds", domain_id=domain, interface="lo", joints=("lift", "shoulder", "elbow"))
    wait_for(lambda: arm.stats.get("joint_states", 0) >= 5, 10, "JointStates from the Cyclone robot",
             lambda: f"{arm.stats}")
    wait_for(lambda: arm.verbs.matched() == "", 10, "the robot's trajectory reader matched")
    bus = seeing(net, "cmd")
    reply = send_command(bus, "arm", "joints/set", {"names": ["shoulder"], "angles": [0.5], "speed": 0.5})
    assert "error" not in reply, reply
    wait_for(lambda: any("names" in json.loads(line) for line in robot.lines), 10, "the trajectory at the robot")
    got = next(json.loads(line) for line in robot.lines if "names" in json.loads(line))
    assert got["names"] == ["shoulder"] and got["positions"][0][0] == 0.5


def test_without_a_robot_the_adapter_says_so_and_a_stop_reaches_no_controller(net, caplog):
    caplog.set_level(logging.WARNING)
    domain = _domain(15)
    arm = start_arm(net, middleware="dds", domain_id=domain, interface="lo")
    answer = send_command(seeing(net, "cmd"), "arm", "stop", {})
    assert answer["reached"] is False and "reached no controller" in answer["error"], answer
    wait_for(lambda: f"no ROS publisher matched on rt/joint_states (domain {domain})" in caplog.text, 10,
             "the adapter saying no publisher matched", lambda: caplog.text[-500:])
    assert arm.stats.get("joint_states", 0) == 0


def test_a_robot_that_matches_but_sends_nothing_is_told_apart(net, spawn, caplog):
    caplog.set_level(logging.WARNING)
    domain = _domain(3)
    robot = spawn(sys.executable, str(ROBOT), str(domain), "silent", collect=True,
                  env={**os.environ, "CYCLONEDDS_URI": LOCALHOST})
    wait_for(lambda: robot.lines, 10, "the Cyclone robot ready")
    start_arm(net, middleware="dds", domain_id=domain, interface="lo")
    wait_for(lambda: "no JointState after" in caplog.text, 10, "the adapter's word on the silence")
    assert f"a ROS publisher matched on rt/joint_states (domain {domain}), but no data arrived" in caplog.text


def test_a_cyclone_robot_discovering_by_multicast_on_loopback_meets_the_same_configuration(topology):  # noqa: F811
    """In a namespace of its own whose ``lo`` has multicast on, a Cyclone robot with Cyclone's
    defaults (discovery and data by multicast) and the adapter's link as documented meet."""
    ns = topology.namespace("dds")
    ip("-n", ns, "link", "set", "lo", "multicast", "on")
    ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "lo")
    env = {k: v for k, v in os.environ.items() if k != "CYCLONEDDS_URI"}
    domain = _domain(7)
    robot = topology.track(NsProcess(["ip", "netns", "exec", ns, sys.executable, str(ROBOT), str(domain)], env=env))
    probe = topology.track(NsProcess(["ip", "netns", "exec", ns, sys.executable, str(PROBE), str(domain),
                                      str(ARM_URDF)], env=env))
    wait_for(lambda: any("names" in json.loads(line) for line in probe.lines), 10,
             "a JointState at the adapter's link", topology.report)
    assert json.loads(probe.lines[1])["names"] == ["shoulder", "elbow", "lift"]
    wait_for(lambda: any("names" in json.loads(line) for line in robot.lines), 10, "a trajectory at the robot",
             topology.report)


def test_the_users_cyclonedds_uri_is_honoured_with_the_interface_selected_once(net, spawn, monkeypatch):
    """A robot whose Cyclone configuration has a discovery tag (participants with another tag
    ignore it) is met only through the user's ``CYCLONEDDS_URI``, which also selects the
    interface the installation names (Cyclone would otherwise have it twice)."""
    domain = _domain(22)
    tagged = LOCALHOST.replace("<Discovery>", "<Discovery><Tag>lab</Tag>")
    robot = spawn(sys.executable, str(ROBOT), str(domain), collect=True, env={**os.environ, "CYCLONEDDS_URI": tagged})
    wait_for(lambda: robot.lines, 10, "the Cyclone robot ready")
    monkeypatch.setenv("CYCLONEDDS_URI", tagged)
    arm = start_arm(net, middleware="dds", domain_id=domain, interface="lo")
    wait_for(lambda: arm.stats.get("joint_states", 0) >= 5, 10, "JointStates from the tagged robot",
             lambda: f"{arm.stats}")
    assert "CYCLONEDDS_URI" in arm.link.where


def test_on_a_loopback_without_multicast_the_adapter_joins_no_multicast_group(topology):  # noqa: F811
    """Cyclone presumes multicast on loopback; where ``lo``'s flag is off (as on a machine's
    own), the adapter neither joins nor sends SPDP multicast there: unicast to 127.0.0.1 only."""
    ns = topology.namespace("dds")
    probe = topology.track(NsProcess(["ip", "netns", "exec", ns, sys.executable, str(PROBE), str(_domain(11)),
                                      str(ARM_URDF)]))
    wait_for(lambda: probe.lines, 10, "the adapter's link open", topology.report)
    groups = subprocess.run(["ip", "netns", "exec", ns, "cat", "/proc/net/igmp"], capture_output=True, text=True,
                            check=True).stdout
    assert "0100FFEF" not in groups, groups  # 239.255.0.1, DDS's SPDP group
