"""The asyncio host (bus/web.py): an HTTP/WebSocket server inside a node's lifecycle,
through the plug-in's ``ws-value`` adapter (the example of docs/adapters.md) and a
test-local adapter whose server crashes. Real sockets, a real aiohttp client."""

from __future__ import annotations

import asyncio
import json
import logging
import re
import signal
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import aiohttp
import pytest
from aiohttp import web
from sonibus_testplugin.ws_value import ValueServer, ValueServerConfig

from sonibus.bus import Adapter, ConfigError, decode, keys
from sonibus.bus.web import WebServer

from .conftest import SONIBUS, free_port, wait_for
from .wakes import wakes

ROOT = Path(__file__).resolve().parent.parent
STOP_WITHIN_S = 3.0   # the node's contract (docs/adapters.md)
RECEIVE_S = 10.0      # generous: a busy 2-core machine


def value_server(net, robot: str = "pepper", port: int = 0) -> ValueServer:
    return net.start(ValueServer(ValueServerConfig(robot=robot, port=port), name="web"))


async def next_value(ws: aiohttp.ClientWebSocketResponse) -> dict:
    message = await ws.receive(timeout=RECEIVE_S)
    assert message.type == aiohttp.WSMsgType.TEXT, message
    return json.loads(message.data)


async def closed_by_server(ws: aiohttp.ClientWebSocketResponse) -> aiohttp.WSMessage:
    """The first message that is not a value: the server's close."""
    while True:
        message = await ws.receive(timeout=RECEIVE_S)
        if message.type != aiohttp.WSMsgType.TEXT:
            return message


def web_threads(name: str) -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == f"{name}:web"]


def refused(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) != 0


def test_a_websocket_client_receives_the_joint_and_http_get_answers(net):
    net.sim("pepper", rate_hz=50)
    server = value_server(net)
    assert server.web.port > 0  # port 0: the bound one is known once start() returned

    async def scenario() -> tuple[list[dict], dict]:
        async with aiohttp.ClientSession(server.web.url) as http:
            async with http.ws_connect("/ws") as ws:
                values = [await next_value(ws) for _ in range(3)]
            async with http.get("/value") as response:
                assert response.status == 200
                assert response.content_type == "application/json"
                return values, await response.json()

    values, latest = asyncio.run(scenario())
    for value in values:
        assert value.keys() == {"robot", "joint", "t", "v"}
        assert (value["robot"], value["joint"]) == ("pepper", "HeadYaw")
        assert isinstance(value["v"], float) and -2.1 < value["v"] < 2.1  # HeadYaw's limits, radians
    assert [v["t"] for v in values] == sorted(v["t"] for v in values)
    assert values[0]["t"] < values[-1]["t"]
    assert latest["joint"] == "HeadYaw" and latest["t"] >= values[-1]["t"]


def test_a_broadcast_from_another_thread_reaches_every_client_in_order(net):
    server = value_server(net, robot="nobody")  # no samples: only the test's broadcasts
    count = 200

    async def client(http: aiohttp.ClientSession, connected: asyncio.Event, clients: list) -> list[int]:
        async with http.ws_connect("/ws") as ws:
            clients.append(ws)
            if len(clients) == 2:
                connected.set()
            return [(await next_value(ws))["n"] for _ in range(count)]

    async def scenario() -> list[list[int]]:
        connected, clients = asyncio.Event(), []
        async with aiohttp.ClientSession(server.web.url) as http:
            receiving = [asyncio.create_task(client(http, connected, clients)) for _ in range(2)]
            await asyncio.wait_for(connected.wait(), RECEIVE_S)
            # the server registers a client after the handshake: wait until it counts both
            await asyncio.to_thread(wait_for, lambda: server.web.clients == 2, what="both clients")
            await asyncio.to_thread(lambda: [server.web.broadcast({"n": n}) for n in range(count)])
            return await asyncio.gather(*receiving)

    assert asyncio.run(scenario()) == [list(range(count))] * 2
    assert server.web.latest == {"n": count - 1}
    assert server.web.dropped == 0


def test_submit_runs_a_coroutine_on_the_servers_loop_from_another_thread(net):
    server = value_server(net, robot="nobody")

    async def where() -> str:
        await asyncio.sleep(0)
        return threading.current_thread().name

    assert server.web.submit(where()).result(timeout=RECEIVE_S) == "web:web"  # the node's worker "web"
    server.stop()
    with pytest.raises(RuntimeError, match="not running"):
        server.web.submit(where())


def test_the_node_stops_within_3_s_with_a_client_connected_and_leaves_nothing_running(net):
    net.sim("pepper", rate_hz=50)
    server = value_server(net)
    port = server.web.port

    async def scenario() -> tuple[float, aiohttp.WSMessage]:
        async with aiohttp.ClientSession(server.web.url) as http, http.ws_connect("/ws") as ws:
            await next_value(ws)
            started = time.monotonic()
            await asyncio.to_thread(server.stop)
            took = time.monotonic() - started
            return took, await closed_by_server(ws)

    took, close = asyncio.run(scenario())
    assert took < STOP_WITHIN_S
    assert close.type == aiohttp.WSMsgType.CLOSE and close.data == aiohttp.WSCloseCode.GOING_AWAY, close
    assert close.extra == "node stopping"
    assert server.state == "stopped"
    assert web_threads("web") == []
    assert refused(port)


def test_a_client_that_never_answers_the_close_does_not_hold_the_stop(net):
    server = value_server(net, robot="nobody")
    with socket.create_connection(("127.0.0.1", server.web.port), timeout=RECEIVE_S) as raw:
        raw.sendall(b"GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                    b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
        assert raw.recv(4096).startswith(b"HTTP/1.1 101")
        wait_for(lambda: server.web.clients == 1, what="the server to count the client")
        started = time.monotonic()
        server.stop()  # the client reads nothing and never sends its close frame
        assert time.monotonic() - started < STOP_WITHIN_S
    assert web_threads("web") == []


def test_sonibus_run_with_the_ws_adapter_ends_on_sigint_with_a_client_connected(net, spawn, tmp_path):
    port = free_port()
    show = tmp_path / "show.toml"
    show.write_text(f'[bus]\nmulticast = false\nconnect = ["{net.endpoint}"]\n\n'
                    '[nodes.pepper]\nadapter = "sim"\nrate_hz = 50\n\n'
                    f'[nodes.web]\nadapter = "ws-value"\nport = {port}\n')
    net.cli_args()  # the network's listening session
    process = spawn(SONIBUS, "run", str(show))

    async def connect(http: aiohttp.ClientSession) -> aiohttp.ClientWebSocketResponse:
        deadline = time.monotonic() + RECEIVE_S
        while True:
            try:
                return await http.ws_connect("/ws")
            except aiohttp.ClientConnectorError:
                if time.monotonic() > deadline or process.popen.poll() is not None:
                    raise
                await asyncio.sleep(0.05)

    async def scenario() -> tuple[dict, float, tuple[int, str, str], aiohttp.WSMessage]:
        async with aiohttp.ClientSession(f"http://127.0.0.1:{port}") as http:
            ws = await connect(http)
            async with ws:
                value = await next_value(ws)
                started = time.monotonic()
                ended = await asyncio.to_thread(process.stop, signal.SIGINT, STOP_WITHIN_S + 2)
                took = time.monotonic() - started
                return value, took, ended, await closed_by_server(ws)

    value, took, (rc, out, err), close = asyncio.run(scenario())
    assert value["joint"] == "HeadYaw"
    assert rc == 130, (rc, err)  # interrupted (Ctrl-C), as every `sonibus run`
    assert took < STOP_WITHIN_S
    assert close.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED), close
    assert "running pepper (sim), web (ws-value)" in out  # adapter names, as in the file
    for noise in ("Traceback", "Task was destroyed", "Unclosed", "Exception ignored", "never retrieved"):
        assert noise not in err, err


@dataclass(frozen=True)
class FragileConfig:
    port: int = 0


class Fragile(Adapter):
    """A server with one broken request handler and one that breaks the server itself."""

    Config = FragileConfig

    def _start(self) -> None:
        self.web = WebServer(self, port=self.config.port)
        self.web.app.router.add_get("/bad", self.bad_request)
        self.web.app.router.add_get("/crash", self.crash)
        self.web.app.router.add_get("/crash-task", self.crash_task)
        self.web.app.router.add_get("/stuck", self.stuck)
        self.web.app.router.add_get("/ws-bad", self.bad_websocket)
        self.web.start()

    async def bad_request(self, request: web.Request) -> web.Response:
        raise ValueError("this request only")

    async def crash(self, request: web.Request) -> web.Response:
        asyncio.get_running_loop().call_soon(self.explode)  # server code outside any request
        return web.Response(text="ok")

    async def bad_websocket(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse()
        await ws.prepare(request)
        await ws.send_str("hello")
        raise ValueError("this connection only")

    async def crash_task(self, request: web.Request) -> web.Response:
        asyncio.get_running_loop().create_task(self.explode_later())  # a task nobody awaits
        return web.Response(text="ok")

    def explode(self) -> None:
        raise RuntimeError("the server's own code broke")

    async def explode_later(self) -> None:
        await asyncio.sleep(0)
        self.explode()

    async def stuck(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse()
        await ws.prepare(request)
        await asyncio.Event().wait()  # never reads, never returns
        return ws


def test_a_handler_that_never_returns_is_cancelled_within_the_stop(net, caplog):
    node = net.start(Fragile(name="fragile"))

    async def scenario() -> tuple[float, aiohttp.WSMessage]:
        async with aiohttp.ClientSession(node.web.url) as http, http.ws_connect("/stuck") as ws:
            started = time.monotonic()
            await asyncio.to_thread(node.stop)
            return time.monotonic() - started, await ws.receive(timeout=RECEIVE_S)

    took, message = asyncio.run(scenario())
    assert took < STOP_WITHIN_S
    assert message.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED), message
    assert node.state == "stopped" and not node.failure
    assert web_threads("fragile") == []
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING], caplog.text  # no "Task was destroyed"


def test_a_failing_request_is_a_500_and_the_server_goes_on(net, caplog):
    caplog.set_level(logging.WARNING)
    node = net.start(Fragile(name="fragile"))

    async def scenario() -> list[int]:
        async with aiohttp.ClientSession(node.web.url) as http:
            statuses = []
            for path in ("/bad", "/bad", "/nope"):
                async with http.get(path) as response:
                    statuses.append(response.status)
            return statuses

    async def websocket() -> list[aiohttp.WSMsgType]:
        async with aiohttp.ClientSession(node.web.url) as http, http.ws_connect("/ws-bad") as ws:
            return [(await ws.receive(timeout=RECEIVE_S)).type for _ in range(2)]

    assert asyncio.run(scenario()) == [500, 500, 404]
    # an open WebSocket cannot become a 500: its connection ends, cleanly (no bytes of an HTTP answer in it)
    assert asyncio.run(websocket()) == [aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.CLOSED]
    assert node.state == "running" and not node.failure
    assert node.stats["errors"] == 3
    warned = [r.getMessage() for r in caplog.records if r.name == "sonibus.bus.adapter"]
    assert len(warned) == 1, warned  # one line, not one per request
    assert warned[0].startswith("fragile: GET /bad failed: ValueError: this request only"), warned


@pytest.mark.parametrize("path", ["/crash", "/crash-task"])
def test_an_exception_escaping_the_server_fails_the_node_with_an_event(net, path):
    watcher = net.bus("watcher")
    subscriber, events = watcher.subscribe(keys.NODE_EVENTS)
    node = net.start(Fragile(name="fragile"))
    wait_for(lambda: watcher.alive(keys.node_token(node.bus.host, "fragile")), what="the node on the bus")

    async def crash() -> int:
        async with aiohttp.ClientSession(node.web.url) as http, http.get(path) as response:
            return response.status

    assert asyncio.run(crash()) == 200
    wait_for(lambda: node.state == "failed", what="the node to fail")
    assert node.failure == "worker 'web' failed: RuntimeError: the server's own code broke"
    key, payload = wait_for(lambda: events.get(timeout=0.1), what="the node event")
    assert key == keys.NODE_EVENTS
    assert decode(payload) | {"t": 0} == {"t": 0, "kind": "node", "host": node.bus.host, "node": "fragile",
                                          "adapter": "Fragile", "state": "failed", "error": node.failure}
    wait_for(lambda: web_threads("fragile") == [], what="the server's thread to end")
    assert refused(node.web.port)
    subscriber.undeclare()


def test_a_port_in_use_is_a_one_line_error_naming_the_key_and_the_fix(net):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        server = ValueServer(ValueServerConfig(robot="nobody", port=port), name="web")
        with pytest.raises(ConfigError) as caught:
            server.start(net.bus("web"))
    assert str(caught.value) == (f"key 'port': cannot listen on 127.0.0.1:{port}: Address already in use — "
                                 "choose a free port (0: any)")
    assert server.state == "stopped"
    assert web_threads("web") == []


def test_an_address_not_of_this_machine_is_named_as_such(net):
    server = ValueServer(ValueServerConfig(robot="nobody", host="203.0.113.7", port=0), name="web")
    with pytest.raises(ConfigError) as caught:
        server.start(net.bus("web"))
    assert str(caught.value).startswith("key 'host': cannot listen on 203.0.113.7:0: ")
    assert str(caught.value).endswith("203.0.113.7 is not an address of this machine (127.0.0.1: this machine "
                                      "only, 0.0.0.0: all)")  # not "choose a free port"
    assert server.state == "stopped" and web_threads("web") == []


def test_the_docs_example_is_the_plugins_ws_value_adapter():
    docs = (ROOT / "docs" / "adapters.md").read_text()
    section = docs.partition("## Serving HTTP and WebSocket")[2]
    example = re.search(r"```python\n(.*?)```", section, re.DOTALL)
    assert example, "no python example in the section"
    plugin = ROOT / "tests" / "plugin" / "sonibus_testplugin" / "ws_value.py"
    assert example[1] == plugin.read_text()


def test_malformed_requests_are_one_counted_line_not_tracebacks(net, caplog):
    """A 9,000-byte path (a port scanner on the LAN) was a 400 and a multi-line traceback
    on the operator's terminal for each request, counted nowhere."""
    caplog.set_level(logging.DEBUG)
    node = value_server(net)
    for _ in range(3):
        with socket.create_connection(("127.0.0.1", node.web.port), timeout=5) as sock:
            sock.sendall(b"GET /" + b"a" * 9000 + b" HTTP/1.1\r\nHost: x\r\n\r\n")
            assert sock.recv(64).split(b" ")[1] == b"400"
    wait_for(lambda: node.stats["bad"] == 3, what="three requests counted bad")
    assert "Traceback" not in caplog.text and "Error handling request" not in "".join(
        r.getMessage() for r in caplog.records if r.name.startswith("aiohttp"))
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warned) == 1 and "LineTooLong" in warned[0] and "\n" not in warned[0], warned
    assert node.state == "running"


def test_an_ipv6_server_gives_a_url_a_client_can_use(net):
    """http://::1:port is no URL (aiohttp refuses it): an IPv6 host goes in brackets."""
    server = net.start(ValueServer(ValueServerConfig(robot="pepper", host="::1", port=0), name="web6"))
    assert server.web.url == f"http://[::1]:{server.web.port}"

    async def scenario() -> int:
        async with aiohttp.ClientSession(server.web.url) as http, http.get("/value") as response:
            return response.status
    assert asyncio.run(scenario()) == 200  # answered, over IPv6


def test_an_idle_web_server_sleeps_until_its_node_stops(net):
    """With no client, the server's loop thread does not wake to look at ``stopping`` (it was
    20 times a second in every web server of a show: an idle process's share); the node's stop
    still ends it at once."""
    server = value_server(net)
    [thread] = web_threads("web")
    counted = wakes([thread], 1.0)
    assert counted["web:web"] <= 5, counted  # (before: 20 or more, STOP_POLL_S = 0.05)
    started = time.monotonic()
    server.stop()
    assert not thread.is_alive() and time.monotonic() - started < STOP_WITHIN_S
