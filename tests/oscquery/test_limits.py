"""Issue 26, item 8: OSCQuery refuses what a web page of another site (or one that renamed
itself to this machine's address: DNS rebinding) asks, on HTTP and on its WebSocket, as the
web node does; LISTENs are bounded per client; 20 clients of 4,096 LISTENs each cost little
and give it back when they leave (they kept +88 MB)."""

from __future__ import annotations

import asyncio
import json
import time
from pathlib import Path

import aiohttp
import pytest
import requests

from ..conftest import SONIBUS, Network, free_port, wait_for
from .conftest import Served

FOREIGN = [({"Origin": "http://evil.example"}, "a page of another site"),
           ({"Host": "evil.example:5678"}, "is not a name of this machine")]


@pytest.mark.parametrize(("headers", "said"), FOREIGN)
def test_a_foreign_origin_or_host_is_refused_on_http_and_websocket(served: Served, headers, said):
    response = requests.get(served.url + "/pepper/joints/HeadYaw", headers=headers, timeout=5)
    assert response.status_code == 403 and said in response.text

    async def websocket() -> int:
        async with aiohttp.ClientSession() as session:
            try:
                await session.ws_connect(served.url.replace("http", "ws") + "/", headers=headers)
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status
        return 101

    assert asyncio.run(websocket()) == 403
    assert served.node.stats["refused"] == 2


@pytest.mark.parametrize("headers", [{}, {"Host": "localhost"}, {"Host": "robots.local:5678"},
                                     {"Origin": "http://127.0.0.1:{port}", "Host": "127.0.0.1:{port}"}])
def test_programs_and_pages_of_this_server_are_served(served: Served, headers):
    port = served.node.web.port
    headers = {k: v.format(port=port) for k, v in headers.items()}
    assert requests.get(served.url + "/pepper/joints/HeadYaw", headers=headers, timeout=5).status_code == 200


def rss(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError(f"no VmRSS for {pid}")


def test_twenty_clients_of_4096_listens_cost_little_and_give_it_back(net: Network, spawn, tmp_path, figure):
    port = free_port()
    show = tmp_path / "show.toml"
    show.write_text(f'[bus]\nmulticast = false\nconnect = ["{net.endpoint}"]\n\n[nodes.pepper]\nadapter = "sim"\n'
                    f'rate_hz = 50\n\n[nodes.oscquery]\nadapter = "oscquery"\nlisten = "127.0.0.1:{port}"\n'
                    'mdns = false\n')
    net.cli_args()
    process = spawn(SONIBUS, "run", str(show))
    url = f"http://127.0.0.1:{port}"

    def served() -> bool:
        try:
            return requests.get(url + "/pepper/joints/HeadYaw", timeout=2).status_code == 200
        except requests.ConnectionError:
            return False

    wait_for(served, 30, "pepper served")
    before = rss(process.popen.pid)
    paths = [f"/made/up/{'p' * 1000}/{i}" for i in range(4096)]

    async def clients() -> int:
        async with aiohttp.ClientSession() as session:
            sockets = [await session.ws_connect(url.replace("http", "ws") + "/") for _ in range(20)]
            for ws in sockets:
                for path in paths:
                    await ws.send_str(json.dumps({"COMMAND": "LISTEN", "DATA": path}))
                await ws.send_str("/?HOST_INFO")  # answered once the LISTENs before it are taken
                await ws.receive(timeout=30)
            connected = rss(process.popen.pid)
            for ws in sockets:
                await ws.close()
        return connected

    connected = asyncio.run(clients())
    time.sleep(1.0)  # (the server sees them leave)
    after = rss(process.popen.pid)
    figure("RSS growth with 20 clients of 4,096 LISTENs", (connected - before) / 1e6, "MB")
    figure("RSS growth after they left", (after - before) / 1e6, "MB")
    assert connected - before < 25e6 and after - before < 25e6, (before, connected, after)
    rc, _, err = process.stop()
    assert rc == 130 and "LISTEN" in err and "not served, and this client already listens to 64 paths" in err, err
