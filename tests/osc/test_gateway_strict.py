"""The gateway takes only well-formed OSC (liblo's rules): the three packets of issue 13,
sent byte for byte over UDP to a gateway in front of a simulated Pepper."""

from __future__ import annotations

import socket
import struct
from dataclasses import dataclass
from typing import Any

import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.adapters.sim import SimRobot

from ..conftest import free_port, wait_for
from .test_gateway import Client, Watch, build, bundle

JOINT_CUT_SHORT = bytes.fromhex(  # /pepper/cmd/joints/set ,sf "HeadYaw" and 1 of the float's 4 bytes
    "2f7065707065722f636d642f6a6f696e74732f73657400002c7366004865616459617700bd")
STIFFNESS_NO_FLOAT = b"/pepper/cmd/stiffness\0\0\0,sf\0Body\0\0\0\0"  # the float's 4 bytes missing
AWARENESS_JUNK = b"/pepper/cmd/awareness\0\0\0,F\0\0" + b"junk-junk-ju"  # 12 bytes after the arguments


@dataclass
class Rig:
    """A simulated Pepper, a gateway in front of it, a client and a watch on the robot's command events."""

    sim: SimRobot
    gate: OscGateway
    client: Client
    commands: Watch


@pytest.fixture
def rig(net):
    sim = net.sim("pepper", rate_hz=50)
    gate = net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{free_port(socket.SOCK_DGRAM)}"),
                                name="gate"))
    client = Client(gate.udp_address)
    yield Rig(sim, gate, client, Watch(net, "pepper/events/command"))
    client.sock.close()


def refused(client: Client, verb: str, fragment: str) -> str:
    """The next reply is ``bad_request`` for ``verb``, one line mentioning ``fragment``."""
    address, args = client.reply()
    assert address == f"/pepper/reply/{verb}" and args[:2] == [0, "bad_request"], (address, args)
    assert fragment in args[2] and "\n" not in args[2], args[2]
    return args[2]


def ran(commands: Watch, verb: str) -> list[dict[str, Any]]:
    """Command events of ``verb`` seen so far that succeeded."""
    return [e for e in commands.all() if e["verb"] == verb and e["ok"]]


def test_a_float_cut_to_one_byte_moves_no_joint(rig, net):
    head = Watch(net, "pepper/joints/HeadYaw")
    start = head.steady(3)
    rig.client.send(JOINT_CUT_SHORT)
    refused(rig.client, "joints/set", "argument 2 (f) needs 4 bytes, 1 left")
    assert rig.gate.stats["malformed"] == 1 and rig.gate.stats["commands"] == 0
    assert head.steady() == start
    assert rig.client.ask("/pepper/cmd/joints/set", "HeadYaw", 0.25, 1.0)[1][0] == 1
    wait_for(lambda: ran(rig.commands, "joints/set"), what="the valid joints/set event")
    assert [e["args"]["angles"] for e in ran(rig.commands, "joints/set")] == [[0.25]]  # never -0.03125
    wait_for(lambda: abs(head.all()[-1]["v"] - 0.25) < 1e-6, what="HeadYaw at 0.25")


def test_stiffness_without_its_value_leaves_pepper_stiff(rig):
    assert set(rig.sim.body.stiffness) == {1.0}
    rig.client.send(STIFFNESS_NO_FLOAT)
    refused(rig.client, "stiffness", "argument 2 (f) needs 4 bytes, 0 left")
    assert set(rig.sim.body.stiffness) == {1.0} and rig.gate.stats["commands"] == 0
    assert rig.client.ask("/pepper/cmd/stiffness", "Head", 0.5)[1][0] == 1
    wait_for(lambda: ran(rig.commands, "stiffness"), what="the valid stiffness event")
    assert [e["args"] for e in ran(rig.commands, "stiffness")] == [{"names": ["Head"], "value": 0.5}]
    assert {rig.sim.body.stiffness[i] for i, n in enumerate(rig.sim.body.names) if n.startswith("Head")} == {0.5}
    assert min(rig.sim.body.stiffness) == 0.5  # nothing went limp


def test_trailing_bytes_after_the_arguments_leave_awareness_on(rig):
    assert rig.client.ask("/pepper/cmd/awareness", True) == \
        ("/pepper/reply/awareness", [1, '{"enabled":true,"previous":false}'])
    rig.client.send(AWARENESS_JUNK)
    refused(rig.client, "awareness", "12 bytes after the last argument")
    assert rig.sim.engine.aware is True
    assert rig.client.ask("/pepper/cmd/awareness", True) == \
        ("/pepper/reply/awareness", [1, '{"enabled":true,"previous":true}'])  # the bad F never ran
    wait_for(lambda: len(ran(rig.commands, "awareness")) == 2, what="both valid awareness events")
    assert [e["args"] for e in ran(rig.commands, "awareness")] == [{"enabled": True}] * 2
    assert rig.gate.stats["malformed"] == 1 and rig.gate.stats["commands"] == 2


def test_a_bundle_with_one_malformed_element_runs_nothing(rig):
    rig.client.send(bundle(build("/pepper/cmd/say", "first"), build("/pepper/cmd/behavior/list"),
                       bundle(STIFFNESS_NO_FLOAT)))
    reasons = {refused(rig.client, verb, "element 3.1: argument 2 (f) needs 4 bytes, 0 left").partition(": ")[2]
               for verb in ("say", "behavior/list", "stiffness")}
    assert len(reasons) == 1  # one packet, one reason, one reply per command in it
    assert rig.client.ask("/pepper/cmd/awareness", 1)[1][0] == 1
    wait_for(lambda: ran(rig.commands, "awareness"), what="the valid awareness event")
    assert {e["verb"] for e in rig.commands.all()} == {"awareness"}
    assert set(rig.sim.body.stiffness) == {1.0} and rig.gate.stats["malformed"] == 1 and rig.client.nothing_waiting()


def test_unreadable_addresses_are_counted_and_warned_once(rig, caplog):
    with caplog.at_level("WARNING", "sonibus"):
        for packet in (b"/pepper/cmd/say", b"/pepper/cmd/sa\0\1,\0\0\0", b"\xff" * 8,
                       bundle(b"\0\0\0\0"), b"#bundle\0" + b"\0" * 7):
            rig.client.send(packet)
        wait_for(lambda: rig.gate.stats["malformed"] == 5, what="five malformed packets counted")
    assert sum("malformed" in r.getMessage() for r in caplog.records) == 1
    assert all("\n" not in r.getMessage() for r in caplog.records)
    assert rig.client.ask("/pepper/cmd/behavior/list")[1][0] == 1 and rig.client.nothing_waiting()
    assert rig.gate.stats["commands"] == 1 and rig.gate.state == "running"


def test_over_tcp_a_malformed_frame_is_answered_on_its_connection(net):
    net.sim("pepper", rate_hz=50)
    gate = net.start(OscGateway(OscGatewayConfig(listen="127.0.0.1:0", tcp="127.0.0.1:0"), name="gate"))
    with socket.create_connection(gate.tcp_address[:2], timeout=5) as conn:
        for packet in (STIFFNESS_NO_FLOAT, build("/pepper/cmd/behavior/list")):  # liblo's size-prefixed frames
            conn.sendall(struct.pack(">i", len(packet)) + packet)
        replies = [OscMessage(frame).params for frame in frames(conn, 2)]
    assert replies[0][:2] == [0, "bad_request"] and "argument 2 (f) needs 4 bytes, 0 left" in replies[0][2]
    assert replies[1][0] == 1 and gate.stats["malformed"] == 1 and gate.stats["commands"] == 1


def frames(conn: socket.socket, count: int) -> list[bytes]:
    """``count`` size-prefixed frames read from ``conn``."""
    data = b""
    out: list[bytes] = []
    while len(out) < count:
        data += conn.recv(65536)
        while len(data) >= 4 and len(data) >= 4 + (size := struct.unpack(">i", data[:4])[0]):
            out.append(data[4:4 + size])
            data = data[4 + size:]
    return out
