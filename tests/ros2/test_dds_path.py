"""A ROS 2 robot on DDS, played by RTI Connext (another vendor's DDS than the Cyclone the
adapter uses, through rticonnextdds-connector: test extra only, its licence is
non-commercial): its JointState drives the OSC sink and the page, and a joints/set from
the page arrives at it as a JointTrajectory within the URDF's limits."""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import rticonnextdds_connector as rti
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import OscSink, OscSinkConfig

from ..conftest import wait_for
from ..web.conftest import start_web
from .conftest import start_arm

XML = Path(__file__).with_name("rti.xml")


@pytest.fixture
def connext(tmp_path) -> Iterator[tuple[rti.Connector, int]]:
    domain = 100 + os.getpid() % 100  # apart from other test runs on this machine
    xml = tmp_path / "rti.xml"
    xml.write_text(XML.read_text().replace('domain_id="DOMAIN"', f'domain_id="{domain}"'))
    connector = rti.Connector("Robots::Arm", str(xml))
    try:
        yield connector, domain
    finally:
        connector.close()


def test_rti_joint_states_drive_the_sinks_and_a_joints_set_reaches_rti(net, connext, websocket):
    connector, domain = connext
    states = connector.get_output("Pub::States")
    trajectories = connector.get_input("Sub::Trajectories")
    arm = start_arm(net, middleware="dds", domain_id=domain, interface="lo",  # as docs/ros2.md says
                    joints=("lift", "shoulder", "elbow"))  # the controller's
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    udp.settimeout(0.05)
    net.start(OscSink(OscSinkConfig(subscribe=("arm/joints/*",), targets=(f"127.0.0.1:{udp.getsockname()[1]}",),
                                    max_age_ms=5000), name="sound"))
    web = start_web(net)
    page = websocket(web.url.replace("http://", "ws://") + "/ws")
    heard: dict[str, float] = {}

    def publish() -> None:
        now = time.time()
        states.instance.set_dictionary({
            "header": {"stamp": {"sec": int(now), "nanosec": int(now % 1 * 1e9)}, "frame_id": ""},
            "name": ["shoulder", "elbow", "lift"], "position": [0.3, -0.4, 0.1], "velocity": [], "effort": []})
        states.write()

    def osc() -> bool:
        publish()
        try:
            message = OscMessage(udp.recv(1024))
            heard[message.address] = message.params[0]
        except TimeoutError:
            pass
        return "/arm/joints/elbow" in heard

    wait_for(osc, 15, "OSC of RTI's joint states", lambda: f"{arm.stats}")
    assert heard["/arm/joints/elbow"] == pytest.approx(-0.4)
    page.wait("frame", robot="arm")

    trajectories.wait_for_publications(10_000)
    page.send({"type": "command", "id": 1, "robot": "arm", "verb": "joints/set",
               "args": {"names": ["shoulder", "lift"], "angles": [1.2, 0.25], "speed": 0.5}})
    reply = page.wait("reply", id=1)
    assert reply["ok"], reply
    trajectories.wait(10_000)
    trajectories.take()
    received = [s.get_dictionary() for s in trajectories.samples.valid_data_iter]
    assert received, "no JointTrajectory at RTI"
    trajectory = received[-1]
    target = dict(zip(trajectory["joint_names"], trajectory["points"][0]["positions"], strict=True))
    assert target["shoulder"] == pytest.approx(1.2) and target["lift"] == pytest.approx(0.25)
    assert list(target) == ["shoulder", "lift"]  # only the joints it sets: the others are not moved
    for name, value in target.items():
        joint = arm.model.joint(name)
        assert joint.min <= value <= joint.max
    duration = trajectory["points"][0]["time_from_start"]
    # the lift's, from the furthest it could be within its limits (heard positions do not count)
    lift = arm.model.joint("lift")
    assert duration["sec"] + duration["nanosec"] * 1e-9 == pytest.approx(
        max(0.25 - lift.min, lift.max - 0.25) / (0.5 * lift.max_velocity), abs=1e-3)
