"""PepperOSC's wire format, as its own patches receive it: Pure Data, raw bytes, oscdump.

PepperOSC sent, for each joint every loop, ``/pepperdata "/<Joint>" "/PositionSensor" <float>``,
once per loop ``/pepperdata "/latency" <seconds>``, and ``/soundstart 1`` / ``/soundstop 1``
around each behavior (docs/design.md, "PepperOSC wire format"). The expected bytes here
are built with python-osc, independently of the sink's encoder.
"""

from __future__ import annotations

import itertools
import re
import socket
import statistics
from collections import defaultdict

import pytest
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import decode, load_model, robot_info, send_command

from ..conftest import free_port, wait_for
from .pd import Datagrams, oscdump_lines, pepperosc_patch, printed, start_oscdump, start_pd

MODEL = load_model("pepper")
YES = "animations/Stand/Gestures/Yes_1"


def commander(net, robot: str = "pepper"):
    """A bus to send commands from, once the robot's queryables have reached it."""
    bus = net.bus("cmd")
    wait_for(lambda: robot_info(bus, robot, timeout=0.5), what=f"{robot}/info")
    return bus


def pepperosc_sink(net, port: int) -> OscSink:
    config = OscSinkConfig(subscribe=("pepper/joints/*", "pepper/events/*"), targets=(f"127.0.0.1:{port}",),
                           profile="pepperosc")
    return net.start(OscSink(config, name="sound"))


def pepperdata(joint: str, value: float) -> bytes:
    builder = OscMessageBuilder("/pepperdata")
    builder.add_arg(f"/{joint}", "s")
    builder.add_arg("/PositionSensor", "s")
    builder.add_arg(value, "f")
    return builder.build().dgram


def latency(seconds: float) -> bytes:
    builder = OscMessageBuilder("/pepperdata")
    builder.add_arg("/latency", "s")
    builder.add_arg(seconds, "f")
    return builder.build().dgram


def cue(address: str) -> bytes:
    builder = OscMessageBuilder(address)
    builder.add_arg(1, "i")
    return builder.build().dgram


LATENCY_PREFIX = latency(0.0)[:-4]
SOUNDSTART, SOUNDSTOP = cue("/soundstart"), cue("/soundstop")


@pytest.fixture
def udp():
    receiver = Datagrams()
    yield receiver
    receiver.close()


def frame_count(udp: Datagrams) -> int:
    return sum(d.startswith(LATENCY_PREFIX) for d in udp.data())


def record(bus):
    """Joint samples as the bus carries them: seq → {joint: (t, v)}, filled as they come."""
    frames: dict[int, dict[str, tuple[float, float]]] = defaultdict(dict)

    def take(sample) -> None:
        message = decode(sample.payload.to_bytes())
        frames[message["seq"]][str(sample.key_expr).rsplit("/", 1)[1]] = (message["t"], message["v"])

    subscriber = bus.session.declare_subscriber("pepper/joints/*", take)
    return subscriber, frames


def test_pepperosc_pd_patch_gets_joints_latency_and_sound_cues(net, spawn, tmp_path):
    port = free_port(socket.SOCK_DGRAM)
    pd = start_pd(spawn, tmp_path, pepperosc_patch(port, "HeadYaw"))
    sink = pepperosc_sink(net, port)
    net.sim("pepper", rate_hz=50)
    bus = commander(net)

    wait_for(lambda: len(printed(pd, "latency")) >= 25, what="half a second of /latency in Pd")
    start = MODEL.posture("StandInit")["HeadYaw"]
    assert float(printed(pd, "HeadYaw")[0]) == pytest.approx(start, abs=1e-5)

    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.5], "speed": 0.5})
    wait_for(lambda: "0.5" in printed(pd, "HeadYaw"), what="HeadYaw 0.5 printed by Pd")
    heads = [float(v) for v in printed(pd, "HeadYaw")]
    assert heads == sorted(heads), "HeadYaw went back while moving up to 0.5"
    assert len(set(heads)) > 3, f"HeadYaw did not move through intermediate values: {heads}"

    send_command(bus, "pepper", "behavior/run", {"name": YES})
    wait_for(lambda: printed(pd, "soundstop"), timeout=6, what="soundstop after the behavior")
    lines = list(pd.lines)
    assert printed(pd, "soundstart") == ["1"] and printed(pd, "soundstop") == ["1"]
    assert lines.index("soundstart: 1") < lines.index("soundstop: 1")

    heads, latencies = printed(pd, "HeadYaw"), [float(v) for v in printed(pd, "latency")]
    # One /latency per frame (0 for the first, and for the rest of a frame the sink had to split).
    assert abs(len(heads) - sum(x > 0 for x in latencies)) <= 2, "one /latency per frame, one HeadYaw per frame"
    assert len(latencies) >= 100
    assert statistics.median(latencies[1:]) == pytest.approx(0.02, abs=0.002)  # the frame interval, in s
    assert all(0 <= x < 1.0 for x in latencies), max(latencies)  # (a stalled machine skips a frame or more)
    assert sink.stats["bad"] == sink.stats["send_errors"] == 0


def test_pepperosc_bytes_are_what_pepperosc_sent(net, udp):
    recorder = net.bus("recorder")
    subscriber, recorded = record(recorder)
    pepperosc_sink(net, udp.port)
    net.sim("pepper", rate_hz=50)
    bus = commander(net)

    wait_for(lambda: frame_count(udp) >= 10, what="ten frames")
    send_command(bus, "pepper", "behavior/run", {"name": YES})
    wait_for(lambda: SOUNDSTART in udp.data(), what="/soundstart")
    send_command(bus, "pepper", "behavior/stop", {"name": YES})
    wait_for(lambda: SOUNDSTOP in udp.data(), what="/soundstop")
    # A slow head turn: every frame has its own HeadYaw, which tells its seq.
    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "speed": 0.1})
    done = frame_count(udp)
    wait_for(lambda: frame_count(udp) >= done + 60, what="sixty frames of a head turn")
    subscriber.undeclare()
    data = udp.data()

    # Sound cues: exactly one of each, in order, never inside a frame.
    assert [d for d in data if not d.startswith(b"/pepperdata\0")] == [SOUNDSTART, SOUNDSTOP]
    frames: list[list[bytes]] = [[]]
    for datagram in data:
        if datagram in (SOUNDSTART, SOUNDSTOP):
            assert frames[-1] == [], "a sound cue arrived in the middle of a frame"
            continue
        frames[-1].append(datagram)
        if datagram.startswith(LATENCY_PREFIX):
            frames.append([])
    frames = frames[:-1]  # the last one may still be arriving
    for frame in frames:
        assert is_frame(frame), f"not joints in order then one /latency: {frame}"

    # Frame seq as the bus carried it: every joint in order, then the time since frame seq - 1.
    def expected(seq: int) -> list[bytes] | None:
        now, before = recorded.get(seq, {}), recorded.get(seq - 1, {})
        if not set(now) == set(before) == set(MODEL.joint_names):
            return None  # the recorder lost a sample (DROP streams under load)
        interval = now["HeadYaw"][0] - before["HeadYaw"][0]
        return [*(pepperdata(j, now[j][1]) for j in MODEL.joint_names), latency(interval)]

    moving: dict[bytes, int] = {}  # HeadYaw datagram → seq, while the head turns
    for seq in sorted(recorded):
        if "HeadYaw" in recorded[seq] and recorded.get(seq - 1, {}).get("HeadYaw", (0, None))[1] not in (
                None, recorded[seq]["HeadYaw"][1]):
            moving[pepperdata("HeadYaw", recorded[seq]["HeadYaw"][1])] = seq
    turning = [(moving[frame[0]], frame) for frame in frames if frame[0] in moving]
    seqs = [seq for seq, _ in turning]
    assert seqs == sorted(set(seqs)), "frames repeated or out of order"
    checked = 0
    for (before, previous), (seq, frame) in itertools.pairwise(turning):
        want = expected(seq)
        if before == seq - 1 and len(previous) == len(frame) == len(MODEL.joints) + 1 and want is not None:
            assert frame == want, f"frame {seq} differs"
            checked += 1
    assert checked >= 25, f"only {checked} whole frames of the head turn to compare"


def is_frame(frame: list[bytes]) -> bool:
    """Some joints (all of them, unless the bus dropped samples) in model order, then one /latency."""
    names = [OscMessage(d).params[0][1:] for d in frame[:-1]]
    order = [n for n in MODEL.joint_names if n in names]
    return (frame[-1].startswith(LATENCY_PREFIX) and bool(names) and names == order
            and all(d[:-4] == pepperdata(n, 0.0)[:-4] for n, d in zip(names, frame, strict=False)))


LINE = re.compile(r'^[0-9a-f]{8}\.[0-9a-f]{8} (?:'
                  r'/pepperdata ssf "/(?P<joint>\w+)" "/PositionSensor" (?P<value>-?\d+\.\d+)'
                  r'|/pepperdata sf "/latency" (?P<latency>\d+\.\d+)'
                  r'|(?P<cue>/soundstart|/soundstop) i 1)$')


def frames_at_oscdump(lines: list[str]) -> int:
    """Whole frames in oscdump's output, after checking every line and every frame's shape."""
    parsed = [LINE.match(line) for line in lines]
    assert all(parsed), [line for line, m in zip(lines, parsed, strict=True) if not m][:3]
    frame: list[str] = []
    whole = 0
    for match in parsed:
        if match["joint"]:
            frame.append(match["joint"])
        elif match["latency"]:
            # Every joint once, in order (a joint may miss when the bus dropped its sample), then /latency.
            assert frame and frame == [j for j in MODEL.joint_names if j in frame], frame
            whole += frame == list(MODEL.joint_names)
            frame = []
        else:
            assert frame == [], "a sound cue inside a frame"
    return whole


def test_oscdump_parses_pepperosc(net, spawn):
    port = free_port(socket.SOCK_DGRAM)
    receiver = start_oscdump(spawn, port)
    pepperosc_sink(net, port)
    net.sim("pepper", rate_hz=50)
    bus = commander(net)
    wait_for(lambda: frames_at_oscdump(oscdump_lines(receiver)) >= 10, timeout=10, what="ten whole frames at oscdump")
    send_command(bus, "pepper", "behavior/run", {"name": YES})
    send_command(bus, "pepper", "behavior/stop", {"name": YES})
    wait_for(lambda: any("/soundstop" in line for line in receiver.lines), what="/soundstop at oscdump")
    lines = oscdump_lines(receiver)
    assert frames_at_oscdump(lines) >= 10
    cues = [m["cue"] for m in map(LINE.match, lines) if m and m["cue"]]
    assert cues == ["/soundstart", "/soundstop"]
