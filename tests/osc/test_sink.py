"""The OSC sink on its own: templates, several targets, bad samples."""

from __future__ import annotations

import socket

import pytest

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import ConfigError, encode

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


BAD_FRAMES = [
    b"\xc1not msgpack",
    b"\x93\x01\x02\x03",                                                       # a list, not a map
    encode({"t": 1.0, "seq": 1, "v": [0.1]}),                                 # no names
    encode({"t": 1.0, "seq": 1, "names": ["HeadYaw", "HeadPitch"], "v": [0.1]}),  # one value short
    encode({"t": 1.0, "seq": 1, "names": ["HeadYaw"], "v": ["high"]}),
    encode({"t": 1.0, "seq": 1, "names": ["Head/Yaw"], "v": [0.1]}),
    encode({"t": 1.0, "seq": 1, "names": ["Head$Yaw"], "v": [0.1]}),              # not one plain key chunk
    encode({"t": 1.0, "seq": 1, "names": ["*"], "v": [0.1]}),
    encode({"t": float("nan"), "seq": 1, "names": ["HeadYaw"], "v": [0.1]}),
]


@pytest.mark.parametrize("per_joint_keys", [False, True], ids=["frames", "joint-keys"])
def test_a_bad_sample_is_skipped_and_the_stream_goes_on(net, spawn, per_joint_keys):
    oscdump = require_tool("oscdump", "liblo-tools")
    port = free_port(socket.SOCK_DGRAM)
    receiver = spawn(oscdump, "-L", str(port), collect=True)
    sink = net.start(OscSink(OscSinkConfig(targets=(f"127.0.0.1:{port}",), per_joint_keys=per_joint_keys),
                             name="sound"))
    other = net.bus("stranger")
    key, bad = ("pepper/joints/HeadYaw", [*BAD_FRAMES[:2], b"\x81\xa1v\xa3str"]) if per_joint_keys \
        else ("pepper/frame", BAD_FRAMES)
    publisher = other.session.declare_publisher(key)
    wait_for(lambda: publisher.matching_status.matching, what="the sink's subscription")
    for payload in bad:
        publisher.put(payload)
    wait_for(lambda: sink.stats["bad"] == len(bad), what=f"{len(bad)} bad messages counted")
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


def test_a_target_nobody_listens_at_is_said_and_gets_the_frames_once_it_listens(net, spawn, caplog):
    """Each target's socket is connected: the "port unreachable" its host answers while
    nothing listens comes back on a later send. It is counted (``unreachable``) and
    warned of once, never taken for a failure: the datagram it was reported on goes too,
    and a receiver started later gets the frames from then on, with no gap."""
    oscdump = require_tool("oscdump", "liblo-tools")
    port = free_port(socket.SOCK_DGRAM)
    caplog.set_level("INFO", logger="sonibus")
    sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/HeadYaw", targets=(f"127.0.0.1:{port}",),
                                           extra=("seq",)), name="sound"))
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: sink.stats["unreachable"] >= 3, what="sends refused while nothing listens")
    assert caplog.text.count(f"nothing listens at udp 127.0.0.1:{port}") == 1
    assert sink.stats["send_errors"] == 0 and sink.state == "running"
    receiver = spawn(oscdump, "-L", str(port), collect=True)
    wait_for(lambda: len(receiver.lines) >= 40, what="frames once a receiver listens")
    seqs = [int(line.split()[-1]) for line in receiver.lines[:40]]
    assert seqs[1:] == list(range(seqs[0] + 1, seqs[0] + 40)), f"a gap once the receiver listens: {seqs}"
    wait_for(lambda: f"something listens at udp 127.0.0.1:{port} now" in caplog.text, what="said once it listens")
    assert sink.stats["send_errors"] == 0
