"""NAOqi 2.9 as far as it can be tried without the robot: ``tcps://`` with a
self-signed certificate (made by ``openssl``, as a robot's is) in front of the
fake robot, and the adapter's login sent inside TLS. What a real 2.9 robot adds
(checking the login) is listed in docs/naoqi.md."""

from __future__ import annotations

from sonibus.bus import robot_info, send_command

from .conftest import attach
from .relay import Relay, self_signed
from .test_stream import f32


def test_adapter_over_tcps_with_user_and_password(net, fakes, tmp_path):
    robot = fakes()
    relay = Relay(int(robot.url.rsplit(":", 1)[1]), self_signed(tmp_path)).start()
    try:
        r = attach(net, relay.url("tcps"), user="nao", password="s3cret", fake=robot)  # waits for a frame
        naoqi = robot_info(r.bus, "pepper")["naoqi"]
        assert naoqi["connected"] is True and naoqi["url"] == relay.url("tcps")
        assert send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.4],
                                                             "speed": 1.0})["targets"] == {"HeadYaw": 0.4}
        r.joints.wait_pose({"HeadYaw": f32(0.4)})
        assert relay.accepted >= 1  # every byte went through the TLS endpoint
        # libqi's login, in its first capability map (user "nao", token = the password)
        assert b"auth_user" in relay.sent and b"auth_token" in relay.sent and b"s3cret" in relay.sent
    finally:
        relay.stop()
