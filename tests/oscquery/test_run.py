"""Issue 16: ``sonibus run`` with an OSCQuery node (advertised by mDNS on its listen
address) serves the namespace, and SIGTERM or Ctrl-C ends it, WebSocket clients told and
the port closed, within the node's 3 s."""

from __future__ import annotations

import json
import signal
import socket
import time

import pytest
import requests

from ..conftest import SONIBUS, free_port, wait_for

SHOW = """
[bus]
multicast = false

[nodes.pepper]
adapter = "sim"
rate_hz = 50

[nodes.gateway]
adapter = "osc-gateway"
listen = "127.0.0.1:{udp}"

[nodes.oscquery]
adapter = "oscquery"
listen = "127.0.0.1:{tcp}"
gateway = "127.0.0.1:{udp}"
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_sonibus_run_serves_and_stops_within_its_time(tmp_path, spawn, websocket, figure, sig):
    tcp, udp = free_port(), free_port(socket.SOCK_DGRAM)
    path = tmp_path / "show.toml"
    path.write_text(SHOW.format(tcp=tcp, udp=udp), encoding="utf-8")
    process = spawn(SONIBUS, "run", str(path), collect=True, merge=True)
    url = f"http://127.0.0.1:{tcp}"

    def served() -> bool:
        try:
            return requests.get(url + "/pepper/joints/HeadYaw", timeout=2).status_code == 200
        except requests.ConnectionError:
            return False
    wait_for(served, 30, "the namespace served", lambda: "\n".join(process.lines))
    assert json.loads(requests.get(url + "/?HOST_INFO", timeout=2).text)["OSC_PORT"] == udp
    client = websocket(url)
    client.send({"COMMAND": "LISTEN", "DATA": "/pepper/joints/HeadYaw"})
    wait_for(lambda: client.messages, what="values")
    begun = time.monotonic()
    code, _, _ = process.stop(sig, timeout=10.0)
    took = time.monotonic() - begun
    figure(f"sonibus run ended after {sig.name}", took, "s")
    assert code in (0, 130, 143), "\n".join(process.lines)
    wait_for(lambda: client.closed, what="the WebSocket closed by the node")
    with pytest.raises(requests.ConnectionError):
        requests.get(url + "/", timeout=2)
    assert not any("Traceback" in line for line in process.lines), "\n".join(process.lines)
