"""Issue 16: a zeroconf browser on another machine finds the OSCQuery server
(``_oscjson._tcp``) and the gateway (``_osc._udp``), and reads the namespace through what it
found with python-oscquery's client; nothing is advertised on an interface not configured.
Two network namespaces on one LAN (tests/net/netns.py) stand for the machines: loopback
has no multicast to rely on."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from ..net.test_multihost import show, started, until

pytestmark = pytest.mark.external

# The browser, run on the other machine: python-oscquery's OSCQueryBrowser (zeroconf), then its client.
BROWSE = """
import json, sys, time
from pythonoscquery.osc_query_browser import OSCQueryBrowser
from pythonoscquery.osc_query_client import OSCQueryClient
browser = OSCQueryBrowser()
deadline = time.monotonic() + float(sys.argv[1])
while time.monotonic() < deadline and not (browser.get_discovered_oscquery() and browser.get_discovered_osc()):
    time.sleep(0.1)
time.sleep(2.0)  # the answers of one round of queries come together: one more would be here by now
found = {"oscjson": [s.name for s in browser.get_discovered_oscquery()],
         "osc": [[s.name, s.port] for s in browser.get_discovered_osc()]}
for service in browser.get_discovered_oscquery():
    client = OSCQueryClient(service)
    found["host"] = client.get_host_info().name
    node = client.query_node("/pepper/joints/HeadYaw")
    found["node"] = node.full_path if node else None
browser.zc.close()
print(json.dumps(found), flush=True)
"""


def test_a_browser_on_the_lan_finds_both_services_and_reads_the_tree(topology, tmp_path):
    server, other = topology.lan("server", "other")
    path = show(tmp_path, f"""
        [bus]
        multicast = false
        [nodes.pepper]
        adapter = "sim"
        rate_hz = 25
        [nodes.gateway]
        adapter = "osc-gateway"
        listen = "{server.address}:9001"
        [nodes.oscquery]
        adapter = "oscquery"
        listen = "{server.address}:5678"
        gateway = "{server.address}:9001"
        name = "robots"
        [nodes.local]
        adapter = "oscquery"
        listen = "127.0.0.1:5679"
        name = "local"
        """)
    running = server.sonibus("run", path)
    started(topology, running)
    script = Path(tmp_path / "browse.py")
    script.write_text(BROWSE, encoding="utf-8")
    browse = other.run(sys.executable, str(script), "15")
    until(topology, lambda: browse.lines or not browse.running, 30, "the browser's answer")
    assert browse.lines, "\n".join(browse.errors[-30:]) + "\nSERVER:" + "\n".join(running.errors[-30:])
    found = json.loads(browse.lines[-1])
    assert found["oscjson"] == ["robots._oscjson._tcp.local."]  # not "local", bound to the server's loopback
    assert found["osc"] == [["robots._osc._udp.local.", 9001]]
    assert found["host"] == "robots" and found["node"] == "/pepper/joints/HeadYaw"
    code, _, errors = running.stop()
    assert code in (0, 130), errors
