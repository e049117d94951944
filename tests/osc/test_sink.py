"""The OSC sink on its own: templates, several targets, bad samples."""

from __future__ import annotations

import socket

import pytest

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import ConfigError

from ..conftest import free_port, require_tool, wait_for


def test_sink_serves_every_target_with_its_template(net, spawn):
    oscdump = require_tool("oscdump", "liblo-tools")
    ports = [free_port(socket.SOCK_DGRAM) for _ in range(2)]
    receivers = [spawn(oscdump, "-L", str(p), collect=True) for p in ports]
    sink = net.start(OscSink(OscSinkConfig(subscribe="nao/joints/Head*", targets=tuple(f"127.0.0.1:{p}" for p in ports),
                                           address="/bot/{robot}/{joint}/pos"), name="sound"))
    net.sim("nao", rate_hz=50)
    for receiver in receivers:
        wait_for(lambda r=receiver: len(r.lines) >= 20, what="OSC at each target")
    for receiver in receivers:
        addresses = {line.split()[1] for line in receiver.lines}
        assert addresses == {"/bot/nao/HeadYaw/pos", "/bot/nao/HeadPitch/pos"}
    assert sink.stats["bad"] == 0


def test_a_bad_sample_is_skipped_and_the_stream_goes_on(net, spawn):
    oscdump = require_tool("oscdump", "liblo-tools")
    port = free_port(socket.SOCK_DGRAM)
    receiver = spawn(oscdump, "-L", str(port), collect=True)
    sink = net.start(OscSink(OscSinkConfig(targets=(f"127.0.0.1:{port}",)), name="sound"))
    other = net.bus("stranger")
    for payload in (b"\xc1not msgpack", b"\x93\x01\x02\x03", b"\x81\xa1v\xa3str"):
        other.session.put("pepper/joints/HeadYaw", payload)
    wait_for(lambda: sink.stats["bad"] == 3, what="three bad samples counted")
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: len(receiver.lines) >= 17, what="good samples after bad ones")
    assert sink.state == "running"


@pytest.mark.parametrize(("options", "fragment"), [
    ({"targets": ()}, "targets is empty"),
    ({"targets": ("localhost",)}, "not host:port"),
    ({"targets": ("localhost:70000",)}, "not host:port"),
    ({"address": "/{robot}/{jiont}"}, "unknown field '{jiont}'"),
    ({"address": "pepper/{joint}"}, "must start with '/'"),
])
def test_bad_options_are_config_errors(options, fragment):
    with pytest.raises(ConfigError, match=fragment.replace("{", r"\{").replace("}", r"\}")):
        OscSinkConfig(**options)
