"""The live ``foxglove`` adapter, seen by a real WebSocket client speaking Foxglove's
protocol: channels advertised with their schemas, a subscription, and binary
messages (opcode 1: subscription id u32, log time u64, payload) that decode to
a frame and to the transforms of that frame; junk from a client harms no one."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import struct
import subprocess
import sys
import time
from typing import Any

import aiohttp
import jsonschema
import numpy as np
import pytest

from sonibus import schemas
from sonibus.adapters.features.kinematics import load_arms
from sonibus.adapters.foxglove import hub
from sonibus.adapters.foxglove.server import FoxgloveConfig, FoxgloveServer
from sonibus.bus.errors import ConfigError
from sonibus.schemas import foxglove

from ..conftest import wait_for
from ..wakes import left_after_stop, named, wakes
from .test_convert import origins

PROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
MESSAGE_DATA = 1  # the server's binary opcode of a message


class Client:
    """One Foxglove WebSocket client: the channels advertised, and messages by subscription id."""

    def __init__(self, ws: aiohttp.ClientWebSocketResponse) -> None:
        self.ws, self.channels, self.server_info = ws, {}, None
        self.said: list[str] = []  # every text message's op (and channel ids): what a timeout reports

    async def until(self, done: Any, timeout: float = 8.0) -> list[tuple[int, int, bytes]]:
        """Read until ``done(messages)`` holds (messages: (subscription, log time, payload))."""
        found: list[tuple[int, int, bytes]] = []
        deadline = time.monotonic() + timeout
        while not done(found):
            left = deadline - time.monotonic()
            assert left > 0, (f"timed out; channels {sorted((t, c['id']) for t, c in self.channels.items())}, "
                              f"{len(found)} messages; the server said {self.said}")
            try:
                message = await self.ws.receive(timeout=left)
            except TimeoutError:
                continue  # (said by the assertion above)
            if message.type == aiohttp.WSMsgType.TEXT:
                data = json.loads(message.data)
                ids = [c.get("id") for c in data.get("channels", [])] + data.get("channelIds", [])
                self.said.append(f"{data['op']} {ids}" if ids else f"{data['op']}: {str(data)[:200]}")
                if data["op"] == "serverInfo":
                    self.server_info = data
                elif data["op"] == "advertise":
                    self.channels.update({c["topic"]: c for c in data["channels"]})
            elif message.type == aiohttp.WSMsgType.BINARY:
                assert message.data[0] == MESSAGE_DATA
                subscription, log_time = struct.unpack_from("<IQ", message.data, 1)
                found.append((subscription, log_time, message.data[13:]))
            else:
                raise AssertionError(f"the server closed the connection: {message}")
        return found

    async def subscribe(self, topics: dict[int, str]) -> None:
        await self.ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sid, "channelId": self.channels[topic]["id"]} for sid, topic in topics.items()]}))


async def connect(session: aiohttp.ClientSession, port: int) -> Client:
    ws = await session.ws_connect(f"ws://127.0.0.1:{port}", protocols=PROTOCOLS)
    assert ws.protocol in PROTOCOLS
    return Client(ws)


def run(coroutine: Any) -> Any:
    return asyncio.run(asyncio.wait_for(coroutine, 30))


@pytest.fixture
def served(net):
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    net.sim("pepper", rate_hz=50)
    return server


def test_a_client_subscribes_and_decodes_a_frame_and_its_transforms(served):
    async def scenario() -> None:
        async with aiohttp.ClientSession() as session:
            client = await connect(session, served.port)
            await client.until(lambda _: {"pepper/frame", "pepper/tf", "pepper/info"} <= client.channels.keys())
            assert client.server_info["name"] == "sonibus"
            for topic, name, schema in [("pepper/frame", "sonibus.v1.frame", schemas.load("frame")),
                                        ("pepper/tf", "foxglove.FrameTransforms",
                                         foxglove.load("foxglove.FrameTransforms")),
                                        ("pepper/joints/HeadYaw", "sonibus.v1.joint_sample",
                                         schemas.load("joint_sample"))]:
                channel = client.channels[topic]
                assert (channel["schemaName"], channel["schemaEncoding"], channel["encoding"]) == \
                    (name, "jsonschema", "json")
                assert json.loads(channel["schema"]) == schema
            await client.subscribe({1: "pepper/frame", 2: "pepper/tf"})
            found = await client.until(lambda got: len({s for s, _, _ in got}) == 2 and len(got) >= 20)
        frames = {}
        transforms = {}
        for subscription, log_time, payload in found:
            assert abs(log_time / 1e9 - time.time()) < 60
            message = json.loads(payload)
            if subscription == 1:
                jsonschema.validate(message, schemas.load("frame"))
                frames[round(message["t"] * 1e9)] = message  # (to 256 ns: a float of 1.7e18)
            else:
                jsonschema.validate(message, foxglove.load("foxglove.FrameTransforms"))
                stamp = message["transforms"][0]["timestamp"]
                transforms[stamp["sec"] * 10**9 + stamp["nsec"]] = message
        both = [t for t in frames if any(abs(t - u) <= 1000 for u in transforms)]
        assert both, "no transforms of a frame that was received"
        for t in both:
            frame = frames[t]
            message = next(m for u, m in transforms.items() if abs(t - u) <= 1000)
            found_origins = origins(message, "pepper/Torso")
            hands = load_arms("pepper").hands(dict(zip(frame["names"], frame["v"], strict=True)))
            assert np.allclose([found_origins["pepper/LHand"], found_origins["pepper/RHand"]], hands, atol=1e-9)

    run(scenario())
    assert served.stats["sent"] > 0


def test_junk_from_a_client_does_not_kill_the_node(served):
    async def scenario() -> None:
        async with aiohttp.ClientSession() as session:
            rude = await connect(session, served.port)
            await rude.until(lambda _: "pepper/frame" in rude.channels)
            await rude.ws.send_str("not json at all")
            await rude.ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 99999}]}))
            await rude.ws.send_str(json.dumps({"op": "no such op"}))
            await rude.ws.send_bytes(b"\x02\xff\xff\xff\xff junk")
            await rude.ws.send_bytes(b"")
            await rude.ws.close()
            polite = await connect(session, served.port)
            await polite.until(lambda _: "pepper/frame" in polite.channels)
            await polite.subscribe({5: "pepper/frame"})
            found = await polite.until(lambda got: len(got) >= 3)
            assert {s for s, _, _ in found} == {5}

    run(scenario())
    assert served.state == "running"


def test_it_stops_and_frees_its_port(net):
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    port = server.port
    assert port > 0
    with socket.create_connection(("127.0.0.1", port), timeout=2):
        pass
    server.stop()
    assert server.state == "stopped"

    def refused() -> bool:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
        except OSError:
            return True
        return False

    wait_for(refused, what="the port to be closed")


def test_a_port_in_use_is_a_one_line_configuration_error(net):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError, match=rf"key 'listen': cannot listen on 127.0.0.1:{port}: .*in use.* — choose"):
            net.start(FoxgloveServer(FoxgloveConfig(listen=f"127.0.0.1:{port}"), name="foxglove"))


@pytest.mark.parametrize(("options", "message"), [
    ({"listen": "nowhere"}, "key 'listen'"),
    ({"queue": 0}, "key 'queue'"),
    ({"info_every_s": 0}, "key 'info_every_s'"),
])
def test_bad_options(options, message):
    with pytest.raises(ConfigError, match=message):
        FoxgloveConfig(**options)


def test_the_adapter_needs_no_foxglove_sdk(tmp_path):
    """The protocol is sonibus's own (wire.py): no extra to install for the adapter."""
    code = ("import sys; sys.modules['foxglove'] = None\n"  # (as if foxglove-sdk were not installed)
            "from sonibus.bus import registry\n"
            "lacking = {}; found = registry.load_all(lacking)\n"
            "print('foxglove' in found, lacking.get('foxglove'))\n")
    # (run outside the clone, as the sonibus command runs: from inside, python -c finds its sonibus.egg-info)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["True", "None"]


@pytest.mark.parametrize("protocols", [("foxglove.sdk.v1",), ("foxglove.websocket.v1",),
                                       ("foxglove.sdk.v1.1", "foxglove.websocket.v1")])
def test_either_subprotocol_is_accepted_and_no_other(served, protocols):
    """Issue 26, item 7c: foxglove-sdk's server refused a client offering only
    foxglove.websocket.v1 (ws-protocol's constant) with HTTP 400."""
    async def scenario() -> tuple[str | None, int]:
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(f"ws://127.0.0.1:{served.port}", protocols=protocols) as ws:
                agreed = ws.protocol
            try:
                await session.ws_connect(f"ws://127.0.0.1:{served.port}", protocols=("foxglove.sdk.v2", "x"))
            except aiohttp.WSServerHandshakeError as exc:
                return agreed, exc.status
            return agreed, 101

    agreed, other = run(scenario())
    assert agreed == next(p for p in protocols if p in PROTOCOLS)
    assert other == 400


def test_bad_subscriptions_and_clients_that_vanish_say_a_few_lines_not_thousands(served, caplog):
    """Issue 26, item 7d: one stderr line per bad subscription and up to 640 'Broken pipe'
    lines per departed client (1,820 lines from 10 clients). Now: counted, warned about at
    most once per WARN_EVERY_S."""
    async def client(session: aiohttp.ClientSession) -> None:
        rude = await connect(session, served.port)
        await rude.until(lambda _: "pepper/frame" in rude.channels)
        await rude.ws.send_str(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1000 + i, "channelId": 900000 + i} for i in range(100)]}))
        await rude.subscribe({i: topic for i, topic in enumerate(rude.channels)})
        await rude.until(lambda got: len(got) >= 10)
        rude.ws._response.connection.transport.abort()  # gone without a close, while subscribed at 50 Hz

    async def scenario() -> None:
        async with aiohttp.ClientSession() as session:
            await asyncio.gather(*(client(session) for _ in range(10)))
        await asyncio.sleep(1.0)  # (what the server does with clients gone: sending to them fails)

    run(scenario())
    wait_for(lambda: served.stats["bad"] >= 1000, what="the bad subscriptions counted")
    lines = [r.getMessage() for r in caplog.records if r.name.startswith("sonibus") and r.levelno >= logging.WARNING]
    assert len(lines) <= 2, lines
    assert served.state == "running"



def test_every_bad_request_is_answered_with_a_status_and_an_unsubscribe_ends_the_messages(served):
    """What the spec asks of a server: a ``status`` for each request it does not take (an error,
    or a warning for an unsubscribe of nothing: it was ignored before, without a word), and no
    message of a subscription once its ``unsubscribe`` is taken (another subscription's messages
    keep the time)."""
    async def read(ws: aiohttp.ClientWebSocketResponse, done: Any) -> list[Any]:
        got: list[Any] = []  # status dicts and subscription ids of messages, in order
        while not done(got):
            message = await ws.receive(timeout=10)
            if message.type == aiohttp.WSMsgType.BINARY:
                got.append(struct.unpack_from("<I", message.data, 1)[0])
            elif message.type == aiohttp.WSMsgType.TEXT and (data := json.loads(message.data))["op"] == "status":
                got.append(data)
        return got

    def statuses(got: list[Any]) -> list[dict[str, Any]]:
        return [g for g in got if isinstance(g, dict)]

    async def scenario() -> tuple[list[Any], list[Any]]:
        async with aiohttp.ClientSession() as session:
            client = await connect(session, served.port)
            await client.until(lambda _: {"pepper/frame", "pepper/joints/HeadYaw"} <= client.channels.keys())
            frame = client.channels["pepper/frame"]["id"]
            await client.subscribe({7: "pepper/frame", 3: "pepper/joints/HeadYaw"})
            for request in [{"op": "subscribe", "subscriptions": [{"id": 7, "channelId": frame}]},   # id used
                            {"op": "subscribe", "subscriptions": [{"id": 8, "channelId": frame}]},   # subscribed
                            {"op": "subscribe", "subscriptions": [{"id": 9, "channelId": 99999}]},   # no channel
                            {"op": "unsubscribe", "subscriptionIds": [12345]},                     # nothing
                            {"op": "getParameters", "parameterNames": []},                          # not served
                            {"op": "subscribe", "subscriptions": [{"id": -1, "channelId": frame}]},  # no id
                            {"op": "unsubscribe", "subscriptionIds": [7]},                         # taken
                            {"op": "unsubscribe", "subscriptionIds": [7]}]:                        # nothing now
                await client.ws.send_str(json.dumps(request))
            answers = await read(client.ws, lambda got: len(statuses(got)) == 7)
            after = await read(client.ws, lambda got: got.count(3) >= 10)  # 10 of HeadYaw: 0.2 s at 50 Hz
            return answers, after

    answers, after = run(scenario())
    assert [s["level"] for s in statuses(answers)] == [2, 2, 2, 1, 2, 2, 1], statuses(answers)
    assert "Unknown subscription ID: 12345" in statuses(answers)[3]["message"]
    assert 7 not in after, after
    assert served.stats["bad"] == 7 and served.state == "running"


def test_messages_wait_for_a_stuck_server_loop_up_to_a_bound_then_are_dropped_counted_and_flow_again(served,
                                                                                                   monkeypatch):
    """What goes to the clients reaches the server's loop in batches (the hub's outbox): a
    loop held up (here: a callback that sleeps 1.5 s) lets at most ``MAX_OUTBOX`` messages
    wait a round of the loop; the rest are dropped and counted, never held without bound, and once the loop
    runs again the client gets the new frames."""
    monkeypatch.setattr(hub, "MAX_OUTBOX", 10)

    async def scenario() -> None:
        async with aiohttp.ClientSession() as session:
            client = await connect(session, served.port)
            await client.until(lambda _: "pepper/frame" in client.channels)
            await client.subscribe({1: "pepper/frame"})
            await client.until(lambda got: len(got) >= 5)
            served.web.call(time.sleep, 1.5)  # the loop held up: nothing goes out meanwhile
            await asyncio.to_thread(wait_for, lambda: served.stats["dropped_for_clients"] > 0, 5,
                                    "messages dropped while the loop is held up")
            after = time.time()
            found = await client.until(lambda got: sum(json.loads(p)["t"] > after for _, _, p in got) >= 10)
            old = len(found) - sum(json.loads(p)["t"] > after for _, _, p in found)
            # (two rounds of the loop after the stall hand a client what waited: the outbox the serve worker
            # filled, and the frames the Handoff held, logged in one batch: each within MAX_OUTBOX)
            assert old <= 2 * 10 + 5, f"{old} messages from before the stall: the outbox held more than its bound"

    run(scenario())
    assert served.state == "running"


def test_an_idle_serve_worker_sleeps_until_a_message_a_robot_or_the_infos_turn(net):
    """Frames go to the server's loop where they arrive; the serve worker sleeps until a message
    comes by its queue, a robot comes or goes, or the infos are due again (``info_every_s``;
    before: a 0.2 s timeout, 5 wake-ups a second; issue 35). Stopped, it ends at once."""
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="idlefox"))
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: server.stats["received"] >= 10 and "pepper" in server._robots, what="pepper at the node")
    counted = wakes(named("idlefox:serve"), 2.0)
    # (the infos sent again at most once, 5 s apart; a count: the GIL's waits count too; before: 10)
    assert counted["idlefox:serve"] <= 5, counted
    assert not left_after_stop(server, "idlefox:")  # (woken by the stop: not left to its join's 2 s)
