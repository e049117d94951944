"""Issue 16: the oscquery node's options — wrong values are one-line errors naming the
key, a port in use names 'listen', and mDNS that cannot start is a warning, not a failure."""

from __future__ import annotations

import socket

import pytest
import requests

from sonibus.adapters.oscquery import OscQuery, OscQueryConfig
from sonibus.bus import ConfigError

from ..conftest import wait_for
from .conftest import serve


@pytest.mark.parametrize(("options", "key"), [
    ({"listen": "nowhere"}, "listen"), ({"gateway": "127.0.0.1:0"}, "gateway"), ({"name": "a.b"}, "name"),
    ({"interfaces": ("eth0",)}, "interfaces"), ({"queue": 0}, "queue"),
    ({"listen": "nowhere.invalid:5678"}, "listen"), ({"gateway": "nowhere.invalid:9001"}, "gateway"),
    ({"interfaces": ("fe80::1",)}, "interfaces"), ({"name": "x" * 64}, "name"), ({"name": "é" * 32}, "name"),
    ({"listen": "[::1]:0"}, "listen"), ({"gateway": "[::1]:9001"}, "gateway"),
])
def test_wrong_options_name_their_key(options, key):
    with pytest.raises(ConfigError, match=f"key '{key}'") as error:
        OscQueryConfig(**options)
    assert str(error.value).count("key '") == 1  # (not "key 'listen': key 'host': ...")


def test_names_are_resolved_and_ipv6_is_fine_without_mdns():
    config = OscQueryConfig(listen="localhost:0", gateway="localhost:9001", name="n" * 63)
    assert (config.listen_address, config.gateway_address) == (("127.0.0.1", 0), ("127.0.0.1", 9001))
    assert OscQueryConfig(listen="[::1]:0", gateway="[::1]:9001", mdns=False).host == "::1"


def test_localhost_with_mdns_starts_and_tells_an_ip_address(net):
    config = OscQueryConfig(listen="localhost:0", gateway="localhost:9001", mdns=True)
    node = net.start(OscQuery(config, name="oscquery"))
    assert node.url.startswith("http://127.0.0.1:") and node.state == "running"
    assert requests.get(node.url + "/?HOST_INFO", timeout=5).json()["OSC_IP"] == "127.0.0.1"


def test_a_port_in_use_names_listen(net):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        node = OscQuery(OscQueryConfig(listen=f"127.0.0.1:{port}", mdns=False), name="oscquery")
        with pytest.raises(ConfigError, match=f"key 'listen': cannot listen on 127.0.0.1:{port}"):
            node.start(net.bus("oscquery"))
        assert node.state == "stopped"


def test_mdns_that_cannot_start_is_a_warning_and_the_server_serves(net, caplog):
    net.sim("pepper", rate_hz=25)
    served = serve(net, mdns=True, interfaces=("203.0.113.7",))  # (no interface has it: binding fails)
    wait_for(lambda: any("not advertised by mDNS on 203.0.113.7" in r.getMessage() for r in caplog.records),
             what="the warning")
    served.wait_node("/pepper/joints/HeadYaw")
    assert served.node.state == "running" and served.node.metrics()["robots"] == 1


def test_a_loopback_gateway_told_to_other_machines_is_warned_about(net, caplog):
    serve(net, listen="0.0.0.0:0")  # (served on every interface, gateway still 127.0.0.1)
    assert any("tells clients on other machines to send commands to themselves" in r.getMessage()
               for r in caplog.records)
