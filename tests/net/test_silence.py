"""Issue 14, item 3: a sink that sees a robot on the bus but receives nothing from it
warns once, naming the robot and the likely causes in order. Here the robot's access
control lets the sound machine see the robot (its liveliness) but not its joints —
the rule a user writes from the key table without `*/frame`. A healthy installation
never warns (tests/net/test_three_machines.py checks its sound machine)."""

from __future__ import annotations

import json
import time

import pytest

from .test_multihost import DATA_MESSAGES, SINK, credentials, show, started, until

pytestmark = pytest.mark.external

SILENCE = "is on the bus but none of its data arrived"


def test_a_sink_refused_the_robots_frames_says_why_once(topology, tmp_path):
    robot, sound = topology.lan("robot", "sound")
    users = tmp_path / "users.txt"
    users.write_text("sound:sound-secret\nrobot:robot-secret\n", encoding="utf-8")
    endpoint = robot.endpoint()
    path = show(tmp_path, f"""
        [bus]
        mode = "peer"
        multicast = false
        connect = ["{endpoint}"]
        [bus.hosts.robot]
        connect = []
        listen = ["{endpoint}"]
        user = "robot"
        password = "robot-secret"
        users_file = "{users}"
        [bus.hosts.robot.access_control]
        default_permission = "deny"
        [[bus.hosts.robot.access_control.rules]]
        id = "data"
        permission = "allow"
        flows = ["egress", "ingress"]
        messages = {json.dumps(DATA_MESSAGES)}
        key_exprs = ["*/joints/**", "*/events/**", "*/info", "sonibus/**"]
        [[bus.hosts.robot.access_control.subjects]]
        id = "sound"
        usernames = ["sound"]
        [[bus.hosts.robot.access_control.policies]]
        rules = ["data"]
        subjects = ["sound"]
        [bus.hosts.sound]
        user = "sound"
        password = "sound-secret"
        [nodes.robot]
        host = "robot"
        adapter = "sim"
        robot = "pepper"
        rate_hz = 25
        [nodes.sound]
        host = "sound"
        subscribe = ["pepper/joints/*", "pepper/events/*"]
        {SINK}
        """)
    dump = sound.oscdump()
    started(topology, robot.sonibus("run", path, "--host", "robot"))
    sink = sound.sonibus("run", path, "--host", "sound")
    started(topology, sink)
    bus = ["--no-multicast", "--connect", endpoint, *credentials("sound", "sound-secret")]
    listed = sound.cli("nodes", *bus)
    assert "1 robot(s)" in listed.stdout, f"the sound machine should see the robot: {listed.stdout} {listed.stderr}"

    warning = until(topology, lambda: [line for line in sink.errors if SILENCE in line], 8.0, "the silence warning")
    line = warning[0]
    assert "robot 'pepper'" in line
    causes = [line.index(cause) for cause in ("access control", "namespace", "per_joint_keys")]
    assert causes == sorted(causes), f"causes out of order: {line}"
    assert "sonibus echo 'pepper/frame'" in line, "how to check"
    assert not dump.messages("/pepper/joints/"), "the ACL lets joints through: no silence to explain"
    time.sleep(2.0)
    assert len([line for line in sink.errors if SILENCE in line]) == 1, "warned more than once"

    echo = sound.cli("echo", "pepper/frame", "--duration", "1", *bus)
    assert echo.returncode == 0 and echo.stdout == ""
    assert "nothing matched 'pepper/frame'" in echo.stderr and "robots on the bus: pepper" in echo.stderr
