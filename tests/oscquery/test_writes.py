"""How the OSCQuery server writes a client's values (issue 35): what one frame brings of the
paths a client LISTENs to goes to it in one transport write, every value still its own
binary WebSocket message, the OSC message's bytes unchanged (it was an aiohttp ``send``,
so a socket write, per value: 17 a frame for a client of every joint)."""

from __future__ import annotations

from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import encode

from ..conftest import wait_for
from .test_stream import osc


def test_a_frames_listened_values_go_to_a_client_in_one_write_each_its_own_message(served, websocket):
    joints = sorted(served.json("/pepper/joints")["CONTENTS"])
    assert len(joints) == 17
    client = websocket(served.url)
    for joint in joints:
        client.send({"COMMAND": "LISTEN", "DATA": f"/pepper/joints/{joint}"})
    wait_for(lambda: len(osc(client)) >= 17, what="a first frame's values")
    (listener,) = served.node.server._clients
    writes: list[int] = []  # bytes of each write to this client's socket, from now on

    def counted() -> None:  # (on the server's loop: what writes to the client, aiohttp's writer too, counted)
        transport = listener.transport
        write = transport.write

        def counting(data: bytes) -> None:
            writes.append(len(data))
            write(data)
        transport.write = counting
    served.node.web.call(counted)
    wait_for(lambda: writes, what="a write counted")
    before = len(client.messages)
    wait_for(lambda: len(client.messages) - before >= 17 * 30, 30, "30 frames' values")
    got = [m for m in list(client.messages)[before:] if isinstance(m, bytes)]
    frames = len(got) / 17
    # one write a frame (a ping or two of the heartbeat aside), not one a value
    assert len(writes) <= frames + 3, f"{len(writes)} writes for {len(got)} values ({frames:.0f} frames)"
    assert sum(writes) >= sum(len(m) + 2 for m in got[17:])  # (each message in a frame of its own: 2-byte header)
    for data in got:  # each value its own OSC message, as the encoder makes it
        message = OscMessage(data)
        assert message.address.removeprefix("/pepper/joints/") in joints
        assert data == encode.message(message.address, *message.params)
