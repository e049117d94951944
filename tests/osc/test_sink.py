"""The OSC sink on its own: templates, several targets, bad samples."""

from __future__ import annotations

import socket
import time

import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import ConfigError, encode

from ..conftest import free_port, require_tool, wait_for
from ..wakes import left_after_stop, named, wakes
from .pd import Datagrams


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


# -- waits: for work, not for time (issue 35) --------------------------------------------


def test_an_idle_sinks_workers_sleep_until_there_is_work(net):
    """With a robot streaming, its frames taken where they arrive, the forward worker has nothing
    to do, and presence's watch nothing until the robot may fall silent: they sleep (before: 0.2 s
    and 0.5 s timeouts, 5 and 2 wake-ups a second). Stopped, they end at once."""
    receiver = Datagrams()
    try:
        sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", targets=(receiver.target,)),
                                 name="idlesink"))
        net.sim("pepper", rate_hz=50)
        wait_for(lambda: len(receiver.data()) >= 10, what="pepper's frames at the target")
        wait_for(lambda: not sink._presence.unsaid, what="pepper's state told (presence's rounds until then)")
        counted = wakes(named("idlesink:"), 3.0)
        # (a count: a thread that waits for the GIL counts a switch too; before: forward 15, silence 6)
        assert counted["idlesink:forward"] <= 3 and counted["idlesink:silence"] <= 3, counted
        assert not left_after_stop(sink, "idlesink:")  # (each woken by the stop: not left to its join's 2 s)
    finally:
        receiver.close()


def test_a_frame_held_for_its_targets_turn_goes_out_with_no_frame_after_it(net):
    """A frame taken where it arrived and held for its target's turn (``max_rate_hz``) wakes the
    forward worker, which sleeps otherwise: it goes out at its turn though no frame follows it."""
    receiver = Datagrams()
    robot = net.bus("fake-bot")
    try:
        net.start(OscSink(OscSinkConfig(subscribe="bot/joints/*", targets=(receiver.target,), max_rate_hz=2),
                          name="held"))

        def frame(value: float) -> None:
            robot.put("bot/frame", {"t": time.time(), "seq": int(value * 10), "names": ["A"], "v": [value]})

        wait_for(lambda: (frame(0.1), receiver.data())[1], what="the first frame at the target")
        frame(0.5)  # within the target's 0.5 s: held for its turn, and nothing after it
        wait_for(lambda: any(OscMessage(d).params == [0.5] for d in receiver.data()), 3,
                 "the held frame at its turn")
    finally:
        receiver.close()
