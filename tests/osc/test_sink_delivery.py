"""What the OSC sink delivers, read by independent receivers: raw UDP parsed with python-osc,
liblo's oscdump and headless Pure Data. Settings as in docs/osc.md."""

from __future__ import annotations

import itertools
import math
import re
import socket
import time
from collections import defaultdict

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage
from pythonosc.osc_packet import OscPacket

from sonibus import schemas
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.osc.encode import NTP_OFFSET
from sonibus.adapters.osc.profiles import EVENT_ARGS
from sonibus.bus import CommandError, decode, encode, load_model, robot_info, send_command

from ..conftest import free_port, wait_for
from .pd import Datagrams, errors, oscdump_lines, printed, receiver_patch, start_oscdump, start_pd

MODEL = load_model("pepper")
JOINTS = MODEL.joint_names
YES = "animations/Stand/Gestures/Yes_1"


def commander(net, robot: str = "pepper"):
    """A bus to send commands from, once the robot's queryables have reached it."""
    bus = net.bus("cmd")
    wait_for(lambda: robot_info(bus, robot, timeout=0.5), what=f"{robot}/info")
    return bus


def f32(value: float) -> float:
    return float(np.float32(value))


def record(bus, pattern: str = "pepper/joints/*"):
    """Samples as the bus carries them: seq → {joint: (t, v)}, filled as they come."""
    frames: dict[int, dict[str, tuple[float, float]]] = defaultdict(dict)

    def take(sample) -> None:
        message = decode(sample.payload.to_bytes())
        frames[message["seq"]][str(sample.key_expr).rsplit("/", 1)[1]] = (message["t"], message["v"])

    return bus.session.declare_subscriber(pattern, take), frames


def head_turn_seqs(recorded) -> dict[float, int]:
    """float32 HeadYaw → seq for the frames where the head moved (each value is one frame's)."""
    out = {}
    for seq, frame in sorted(recorded.items()):
        before = recorded.get(seq - 1, {}).get("HeadYaw")
        if "HeadYaw" in frame and before is not None and before[1] != frame["HeadYaw"][1]:
            out[f32(frame["HeadYaw"][1])] = seq
    return out


def messages(receiver: Datagrams, prefix: str = "") -> list[tuple[str, list]]:
    """(address, args) of every message received, bundles unpacked, in order."""
    out = []
    for dgram in receiver.data():
        for timed in OscPacket(dgram).messages:
            if timed.message.address.startswith(prefix):
                out.append((timed.message.address, timed.message.params))
    return out


def keyed(subscribe, **options) -> OscSinkConfig:
    """A sink config for sources that put joint keys only (a test's bus, not a robot owner)."""
    return OscSinkConfig(subscribe=subscribe, per_joint_keys=True, **options)


def sample(seq: int, v, t: float | None = None) -> dict:
    return {"t": time.time() if t is None else t, "seq": seq, "v": v}


def delivered(receiver: Datagrams, key: str, value=None) -> bool:
    """Whether ``receiver`` got a message from ``key`` (with ``value`` as its last argument, if given),
    under the sonibus address or PepperOSC's /pepperdata."""
    name = key.rsplit("/", 1)[1]
    return any((a == "/" + key or (a == "/pepperdata" and p[:1] == [f"/{name}"])) and (value is None or p[-1] == value)
               for a, p in messages(receiver))


def handshake(src, key: str, receiver: Datagrams, message: dict | None = None, timeout: float = 5.0) -> None:
    """Publish on ``key`` until ``receiver`` gets something from it: the sink's subscription has
    reached ``src`` (until then Zenoh drops what ``src`` publishes)."""

    def arrived() -> bool:
        src.put(key, message or sample(0, 0.0))
        return delivered(receiver, key)

    wait_for(arrived, timeout, what=f"a first message from {key}")


# -- bundles ----------------------------------------------------------------------------

OSCDUMP = re.compile(r"^(?P<sec>[0-9a-f]{8})\.(?P<frac>[0-9a-f]{8}) /pepper/joints/(?P<joint>\w+) f (?P<v>-?\d+\.\d+)$")


def test_bundles_hold_one_frame_each_timed_t_plus_latency(net, spawn, tmp_path, receivers):
    """Raw bytes, oscdump and Pd all read the bundles. oscdump prints each message with its
    bundle's timetag (liblo holds them until then); Pd 0.53's [oscparse] unpacks a bundle
    into its messages at once and drops the timetag."""
    raw = receivers()
    dump_port, pd_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    dump = start_oscdump(spawn, dump_port)
    pd = start_pd(spawn, tmp_path, receiver_patch(pd_port))
    subscriber, recorded = record(net.bus("recorder"))
    targets = (raw.target, f"127.0.0.1:{dump_port}", f"127.0.0.1:{pd_port}")
    net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", targets=targets, bundle=True, latency_ms=50),
                      name="sound"))
    net.sim("pepper", rate_hz=50)
    bus = commander(net)
    wait_for(lambda: len(raw.items) >= 10, what="ten bundles")
    # A slow head turn: each frame has its own HeadYaw, which tells its seq.
    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "speed": 0.1})
    start = len(raw.items)
    wait_for(lambda: len(raw.items) >= start + 50, what="fifty bundles of a head turn")
    subscriber.undeclare()
    by_head = head_turn_seqs(recorded)

    checked = 0
    for dgram in raw.data():
        assert OscBundle.dgram_is_bundle(dgram), dgram[:40]
        bundle = OscBundle(dgram)
        contents = [(m.address, m.params) for m in bundle]
        assert all(re.fullmatch(r"/pepper/joints/\w+", a) and len(p) == 1 for a, p in contents), contents
        joints = [a.rsplit("/", 1)[1] for a, _ in contents]
        assert joints == [j for j in JOINTS if j in joints], "each joint once, in order"
        seq = by_head.get(dict(zip(joints, (p[0] for _, p in contents), strict=True)).get("HeadYaw"))
        if seq is None or joints != list(JOINTS) or set(recorded[seq]) != set(JOINTS):
            continue
        assert bundle.timestamp == pytest.approx(recorded[seq]["HeadYaw"][0] + 0.050, abs=1e-5)
        assert [p[0] for _, p in contents] == [f32(recorded[seq][j][1]) for j in JOINTS]
        checked += 1
    assert checked >= 30, f"{checked} whole bundles of the head turn"

    # oscdump: the bundle's timetag on each of its messages; one frame's t + 50 ms.
    frame_times = sorted(frame["HeadYaw"][0] for frame in recorded.values() if "HeadYaw" in frame)
    wait_for(lambda: len(oscdump_lines(dump)) >= 17 * 30, what="thirty bundles at oscdump")
    groups: dict[float, list[str]] = defaultdict(list)
    for line in oscdump_lines(dump):
        match = OSCDUMP.match(line)
        assert match, line
        tag = int(match["sec"], 16) - NTP_OFFSET + int(match["frac"], 16) / 2**32
        groups[tag].append(match["joint"])
    for tag, joints in groups.items():
        nearest = min(frame_times, key=lambda t, tag=tag: abs(t + 0.050 - tag))
        assert abs(nearest + 0.050 - tag) <= 1e-5, f"timetag {tag} is not a frame's t + 50 ms"
        assert joints == [j for j in JOINTS if j in joints]
    assert sum(joints == list(JOINTS) for joints in groups.values()) >= 25

    # Pd: every message of every bundle, the address split into symbols.
    wait_for(lambda: len(printed(pd, "OSC")) >= 17 * 30, what="thirty bundles' messages in Pd")
    seen = defaultdict(int)
    for line in printed(pd, "OSC"):
        robot, section, joint, value = line.split()
        assert (robot, section) == ("pepper", "joints") and joint in JOINTS
        float(value)
        seen[joint] += 1
    assert set(seen) == set(JOINTS) and min(seen.values()) >= 25
    assert errors(pd) == []


def test_a_lost_sample_does_not_split_the_frames_after_it(net, receivers):
    """Frame B lost J4 on the way (joint streams drop under congestion). B goes out without it,
    and every later frame goes out whole, in one bundle."""
    raw = receivers()
    net.start(OscSink(keyed("toy/joints/*", targets=(raw.target,), bundle=True), name="sound"))
    src = net.bus("toy")
    names = ("J1", "J2", "J3", "J4")
    seq = 0

    def frame(keys=names) -> None:
        nonlocal seq
        seq += 1
        t = time.time()
        for name in keys:
            src.put(f"toy/joints/{name}", sample(seq, seq * 10 + int(name[1]), t))

    def bundles() -> list[list[float]]:
        return [[m.params[0] for m in OscBundle(d)] for d in raw.data()]

    wait_for(lambda: frame() or len(bundles()) >= 3, what="the first bundles")
    last = seq
    wait_for(lambda: [last * 10 + i for i in (1, 2, 3, 4)] in bundles(), what="the last of them whole")
    before = len(bundles())
    first = seq + 1
    frame()
    frame(names[:3])  # J4 lost
    for _ in range(4):
        frame()
    wait_for(lambda: len(bundles()) >= before + 6, timeout=2, what="six more bundles")
    sent = bundles()[before:]
    want = [[s * 10 + i for i in ((1, 2, 3) if s == first + 1 else (1, 2, 3, 4))] for s in range(first, seq + 1)]
    assert sent == want


# -- values -----------------------------------------------------------------------------

def test_normalized_values_follow_the_limits_the_robot_serves(net, receivers):
    raw = receivers()
    subscriber, recorded = record(net.bus("recorder"))
    net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", targets=(raw.target,), values="normalized",
                                    extra=("seq",)), name="sound"))
    net.sim("pepper", rate_hz=50)
    bus = commander(net)
    info = robot_info(bus, "pepper")
    assert {j["name"]: (j["min"], j["max"]) for j in info["joints"]} == {j.name: (j.min, j.max) for j in MODEL.joints}
    send_command(bus, "pepper", "behavior/run", {"name": "animations/Stand/Gestures/Hey_1"})
    wait_for(lambda: len(raw.items) >= 17 * 30, what="thirty frames")
    subscriber.undeclare()

    checked = 0
    for address, (value, seq) in messages(raw):
        joint = address.removeprefix("/pepper/joints/")
        assert 0.0 <= value <= 1.0, (address, value)
        if joint in recorded.get(seq, {}):
            spec = MODEL.joint(joint)
            assert value == pytest.approx((recorded[seq][joint][1] - spec.min) / (spec.max - spec.min), abs=1e-6)
            checked += 1
    assert checked >= 17 * 25


def test_normalized_values_use_info_not_the_model(net, receivers):
    """A robot the sink knows nothing about: ranges come from its <robot>/info only."""
    raw = receivers()
    owner = net.bus("toy")
    joints = [{"name": name, "unit": "rad", "min": low, "max": high, "max_velocity": 1.0}
              for name, low, high in [("A", -2.0, 2.0), ("B", 0.0, 10.0)]]
    info = {"robot": "toy", "model": "toy", "rate_hz": 50.0, "behaviors": [], "postures": [], "adapter": "test",
            "schema_version": schemas.VERSION, "owner": {"host": "h", "node": "toy"}, "joints": joints,
            "derived": [{"name": "hand/RHand", "min": 0.0, "max": 2.0}]}
    queryable = owner.serve("toy/info", lambda query: query.reply(query.key_expr, encode(info)))
    sink = net.start(OscSink(keyed(("toy/joints/*", "toy/derived/**"), targets=(raw.target,),
                                           values="normalized"), name="sound"))
    handshake(owner, "toy/joints/A", raw, sample(0, 1.0))
    assert sink.stats["waiting_info"] >= 1  # what came before the info was not sent raw
    # not in info: held back 3 s (a processor may describe it yet), then sent raw
    handshake(owner, "toy/derived/hello/x", raw, timeout=15)
    for key, v in [("toy/joints/A", 5.0), ("toy/joints/B", -1.0), ("toy/joints/B", 2.5), ("toy/joints/C", 3.3),
                   ("toy/derived/hand/RHand", [0.5, 1.0, 3.0])]:
        owner.put(key, sample(1, v))
    # Joints and derived values come through separate subscriptions: no order between them.
    wait_for(lambda: delivered(raw, "toy/derived/hand/RHand") and delivered(raw, "toy/joints/C"), what="the samples")
    queryable.undeclare()
    joints = [m for m in messages(raw) if m[0].startswith("/toy/joints/")]
    assert all(m == ("/toy/joints/A", [0.75]) for m in joints[:-4]), joints[:-4]  # the handshake: 1.0 in -2..2
    assert joints[-4:] == [("/toy/joints/A", [1.0]), ("/toy/joints/B", [0.0]), ("/toy/joints/B", [0.25]),
                           ("/toy/joints/C", [f32(3.3)])]
    assert [m for m in messages(raw) if m[0] == "/toy/derived/hand/RHand"] == [
        ("/toy/derived/hand/RHand", [0.25, 0.5, 1.0])]


def test_extra_t_and_seq_follow_the_value(net, receivers):
    """``extra = ["t", "seq"]``: ``,fdi`` — the value (float32), t as a double, seq as int32."""
    raw = receivers()
    subscriber, recorded = record(net.bus("recorder"))
    net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", targets=(raw.target,), extra=("t", "seq")),
                      name="sound"))
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: len(raw.items) >= 17 * 20, what="twenty frames")
    subscriber.undeclare()
    checked = 0
    for dgram in raw.data():
        message = OscMessage(dgram)
        assert dgram[len(message.address.encode()) // 4 * 4 + 4:].startswith(b",fdi\0\0\0\0")
        value, t, seq = message.params
        assert isinstance(value, float) and isinstance(t, float) and isinstance(seq, int)
        joint = message.address.removeprefix("/pepper/joints/")
        if joint in recorded.get(seq, {}):
            assert t == recorded[seq][joint][0]  # a double: exactly the sample's t
            assert value == f32(recorded[seq][joint][1])
            checked += 1
    assert checked >= 17 * 15


def test_one_sink_serves_messages_bundles_and_pepperosc_at_once(net, receivers):
    plain, bundled, pepperosc = receivers(), receivers(), receivers()
    targets = (plain.target, {"to": bundled.target, "bundle": True, "latency_ms": 20},
               {"to": pepperosc.target, "profile": "pepperosc"})
    net.start(OscSink(OscSinkConfig(subscribe=("pepper/joints/*", "pepper/events/*"), targets=targets), name="sound"))
    net.sim("pepper", rate_hz=50)
    bus = commander(net)
    send_command(bus, "pepper", "behavior/run", {"name": YES})
    send_command(bus, "pepper", "behavior/stop", {"name": YES})
    for receiver, start in ((plain, b"/pepper/events/behavior"), (bundled, b"/pepper/events/behavior"),
                            (pepperosc, b"/soundstart")):
        wait_for(lambda r=receiver, w=start: sum(d.startswith(w) for d in r.data()) >= 2
                 or any(d.startswith(b"/soundstop") for d in r.data()), what=f"the events at {receiver.target}")
    wait_for(lambda: any(OscBundle.dgram_is_bundle(d) and len(list(OscBundle(d))) == 17 for d in bundled.data()),
             what="a bundle of all 17 joints")
    # (each target in its own time: on a busy machine the PepperOSC one may not have had a frame yet)
    wait_for(lambda: {p[0] for a, p in messages(pepperosc) if a == "/pepperdata"} >= {f"/{j}" for j in JOINTS}
             | {"/latency"}, what="a whole frame at the PepperOSC target")

    joints = {f"/pepper/joints/{j}" for j in JOINTS}
    # Plain target: one message per joint sample, events as messages; no bundles.
    assert not any(OscBundle.dgram_is_bundle(d) for d in plain.data())
    plain_messages = messages(plain)
    assert {a for a, _ in plain_messages} == joints | {"/pepper/events/behavior", "/pepper/events/command",
                                                    "/pepper/events/connection"}  # the robot is there
    # Bundle target: joints only inside bundles (t + 20 ms), events as plain messages.
    for dgram in bundled.data():
        if OscBundle.dgram_is_bundle(dgram):
            assert {m.address for m in OscBundle(dgram)} <= joints
        else:
            assert OscMessage(dgram).address.startswith("/pepper/events/")
    # PepperOSC target: /pepperdata, /soundstart, /soundstop and nothing else.
    addresses = {(a, p[0]) for a, p in messages(pepperosc)}
    assert {a for a, _ in addresses} == {"/pepperdata", "/soundstart", "/soundstop"}
    assert {arg for a, arg in addresses if a == "/pepperdata"} == {f"/{j}" for j in JOINTS} | {"/latency"}
    assert ("/pepper/events/behavior", [YES, "started"]) in plain_messages
    assert ("/pepper/events/behavior", [YES, "stopped"]) in plain_messages


# -- rate cap, deadband, on change --------------------------------------------------------

def test_rate_cap_sends_ten_a_second_and_always_the_newest(net, receivers):
    raw = receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", targets=(raw.target,), max_rate_hz=10),
                             name="sound"))
    net.sim("pepper", rate_hz=50)
    bus = commander(net)

    def arrivals(joint: str) -> list[tuple[float, float]]:
        address = f"/pepper/joints/{joint}"
        return [(at, OscMessage(d).params[0]) for at, d in raw.stamped() if OscMessage(d).address == address]

    wait_for(lambda: len(arrivals("HeadYaw")) >= 16, what="1.5 s of HeadYaw at 10/s")
    received = sink.stats["received"]
    for joint in JOINTS:
        times = [at for at, _ in arrivals(joint)]
        rate = (len(times) - 1) / (times[-1] - times[0])
        # never above the cap; below it only as far as a busy machine delays the sink (bench/pacing.py)
        assert 5 <= rate <= 10.5, f"{joint}: {rate:.1f} messages/s"
        # no burst (a send the machine held up can come a little closer to the next: 98 ms quiet)
        assert min(b - a for a, b in itertools.pairwise(times)) >= 0.05
    assert received >= 17 * 50  # the sink saw the full 50 Hz

    before = len(arrivals("HeadYaw"))
    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.7], "speed": 0.2})
    wait_for(lambda: [v for _, v in arrivals("HeadYaw")][-1] == f32(0.7), what="HeadYaw 0.7 at the target")
    moving = [v for _, v in arrivals("HeadYaw")][before:]
    assert moving == sorted(moving), f"an older value after a newer one: {moving}"
    assert len(moving) >= 3, moving
    wait_for(lambda: len(arrivals("HeadYaw")) >= before + len(moving) + 3, what="three more")
    assert {v for _, v in arrivals("HeadYaw")[before + len(moving):]} == {f32(0.7)}


@pytest.mark.parametrize("options", [{}, {"on_change": True}, {"deadband": 0.01}],
                         ids=["plain", "on_change", "deadband"])
def test_rate_cap_sends_the_newest_of_a_burst_when_its_turn_comes(net, receivers, options):
    """Ten samples at once, then nothing: the first goes out, the newest a turn later, nothing between."""
    raw = receivers()
    net.start(OscSink(keyed("toy/joints/*", targets=(raw.target,), max_rate_hz=10, **options),
                      name="sound"))
    src = net.bus("toy")
    handshake(src, "toy/joints/Hello", raw)
    burst = [round(0.1 * i, 1) for i in range(1, 11)]
    for seq, value in enumerate(burst):
        src.put("toy/joints/Ramp", sample(seq, value))

    def ramp() -> list[tuple[float, float]]:
        parsed = [(at, OscMessage(d)) for at, d in raw.stamped()]
        return [(at, m.params[0]) for at, m in parsed if m.address == "/toy/joints/Ramp"]

    wait_for(lambda: ramp() and ramp()[-1][1] == f32(1.0), timeout=2, what="the newest value, 1.0")
    (first_at, first), (last_at, last) = ramp()
    assert (first, last) == (f32(0.1), f32(1.0))
    assert last_at - first_at >= 0.05  # a turn (100 ms) later, less how long a busy machine held up the first


def test_on_change_and_deadband_send_only_what_moved(net, receivers):
    changes, coarse = receivers(), receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/*", on_change=True,
                                           targets=(changes.target, {"to": coarse.target, "deadband": 0.1})),
                             name="sound"))
    net.sim("pepper", rate_hz=50, idle=False)
    bus = commander(net)
    wait_for(lambda: sink.stats["received"] >= 17 * 25, what="half a second of a still robot")
    for receiver in (changes, coarse):
        assert sorted(a for a, _ in messages(receiver)) == sorted(f"/pepper/joints/{j}" for j in JOINTS)

    send_command(bus, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.8], "speed": 0.3})
    wait_for(lambda: messages(changes)[-1] == ("/pepper/joints/HeadYaw", [f32(0.8)]), what="HeadYaw 0.8")
    received = sink.stats["received"]
    wait_for(lambda: sink.stats["received"] >= received + 17 * 25, what="half a second still at 0.8")

    moved = messages(changes)[17:]
    assert {a for a, _ in moved} == {"/pepper/joints/HeadYaw"}, "only HeadYaw moved"
    values = [p[0] for _, p in moved]
    assert len(values) >= 10 and values == sorted(set(values)), "every value once, rising"
    start = MODEL.posture("StandInit")["HeadYaw"]
    steps = [p[0] for a, p in messages(coarse)[17:]]
    assert all(a == "/pepper/joints/HeadYaw" for a, _ in messages(coarse)[17:])
    assert all(b - a > 0.1 for a, b in zip([f32(start), *steps], steps, strict=False)), steps
    assert 3 <= len(steps) <= (0.8 - start) / 0.1


# -- events -----------------------------------------------------------------------------

def test_events_arrive_with_their_documented_arguments(net, receivers):
    raw = receivers()
    net.start(OscSink(OscSinkConfig(subscribe="pepper/events/*", targets=(raw.target,)), name="sound"))
    net.sim("pepper", rate_hz=50, words_per_minute=600)
    bus = commander(net)
    send_command(bus, "pepper", "behavior/run", {"name": YES})
    send_command(bus, "pepper", "behavior/stop", {"name": YES})
    send_command(bus, "pepper", "say", {"text": "hello"})
    send_command(bus, "pepper", "posture", {"name": "StandZero", "speed": 1.0})
    with pytest.raises(CommandError):
        send_command(bus, "pepper", "behavior/run", {"name": "no/such/behavior"})
    bus.put("pepper/events/connection", {"t": time.time(), "kind": "connection", "state": "lost"})
    bus.put("pepper/events/custom", {"t": time.time(), "kind": "custom", "level": 2, "label": "x", "flag": True,
                                      "list": [1, 2], "ratio": 0.5})
    want = [
        ("/pepper/events/behavior", [YES, "started"]), ("/pepper/events/command", ["behavior/run", 1]),
        ("/pepper/events/behavior", [YES, "stopped"]), ("/pepper/events/command", ["behavior/stop", 1]),
        ("/pepper/events/command", ["say", 1]), ("/pepper/events/speech", ["hello", "started"]),
        ("/pepper/events/speech", ["hello", "done"]),
        ("/pepper/events/posture", ["StandZero", "started"]), ("/pepper/events/command", ["posture", 1]),
        ("/pepper/events/posture", ["StandZero", "reached"]),
        ("/pepper/events/command", ["behavior/run", 0]),
        ("/pepper/events/connection", ["lost"]),
        ("/pepper/events/custom", [1, "x", 2, 0.5]),  # other kinds: scalar fields by name, booleans as ints
    ]
    wait_for(lambda: all(w in messages(raw) for w in want), timeout=5,
             what=f"every event; missing {[w for w in want if w not in messages(raw)]}")
    got = messages(raw)
    for kind, fields in EVENT_ARGS.items():
        for address, args in got:
            if address == f"/pepper/events/{kind}":
                assert len(args) == len(fields), (address, args)
    assert got.index(want[0]) < got.index(want[2])  # started before stopped
    assert got.index(want[5]) < got.index(want[6])
    assert b",si\0" in next(d for d in raw.data() if d.startswith(b"/pepper/events/command\0"))


# -- stale samples ----------------------------------------------------------------------

def test_stale_samples_are_dropped_unless_max_age_is_0(net, receivers):
    fresh_only, everything = receivers(), receivers()
    keeping = net.start(OscSink(keyed("toy/joints/*", targets=(fresh_only.target,)), name="live"))
    keeping_all = net.start(OscSink(keyed("toy/joints/*", targets=(everything.target,),
                                                  max_age_ms=0), name="all"))
    src = net.bus("toy")
    handshake(src, "toy/joints/Hello", fresh_only)
    handshake(src, "toy/joints/Hello", everything)
    for seq in range(5):
        src.put("toy/joints/Old", sample(seq, 0.5, time.time() - 1.0))
    src.put("toy/joints/Fresh", sample(9, 0.25))
    for receiver in (fresh_only, everything):
        wait_for(lambda r=receiver: ("/toy/joints/Fresh", [0.25]) in messages(r), what="the fresh sample")
    assert [p for a, p in messages(fresh_only) if a != "/toy/joints/Hello"] == [[0.25]]
    assert keeping.stats["stale"] == 5
    assert [p for a, p in messages(everything) if a != "/toy/joints/Hello"] == [[0.5]] * 5 + [[0.25]]
    assert keeping_all.stats["stale"] == 0


# -- garbage ----------------------------------------------------------------------------

def test_the_sink_survives_garbage_and_sends_derived_vectors(net, receivers):
    raw = receivers()
    sink = net.start(OscSink(keyed(("pepper/joints/*", "pepper/derived/**", "pepper/events/*"),
                                           targets=(raw.target,)), name="sound"))
    src = net.bus("src")
    handshake(src, "pepper/joints/Hello", raw)
    handshake(src, "pepper/derived/hello/x", raw)
    handshake(src, "pepper/events/hello", raw, {"t": time.time(), "kind": "hello"})
    garbage = [b"\xc1not msgpack", b"\x93\x01\x02\x03", encode({}), encode({"t": time.time(), "seq": 1}),
               encode({"seq": 1, "v": 0.5}), encode({"t": time.time(), "v": 0.5}),
               encode({"t": "now", "seq": 1, "v": 0.5}), encode({"t": time.time(), "seq": 1, "v": None}),
               encode({"t": time.time(), "seq": 1, "v": {"x": 1}}), encode({"t": time.time(), "seq": "x", "v": 0.5})]
    for payload in garbage:
        src.session.put("pepper/joints/HeadYaw", payload)
    src.session.put("pepper/events/behavior", b"\xc1")
    src.put("pepper/derived/hand/RHand", sample(1, [0.1, 0.2, 0.3]))
    src.put("pepper/joints/HeadYaw", sample(2, 0.5))
    wait_for(lambda: delivered(raw, "pepper/joints/HeadYaw") and delivered(raw, "pepper/derived/hand/RHand"),
             what="the good samples after the garbage")
    assert sorted((a, p) for a, p in messages(raw) if "hello" not in a.lower()) == [
        ("/pepper/derived/hand/RHand", [f32(0.1), f32(0.2), f32(0.3)]), ("/pepper/joints/HeadYaw", [0.5])]
    derived = next(d for d in raw.data() if d.startswith(b"/pepper/derived/hand/RHand\0"))
    assert b",fff\0" in derived
    assert sink.stats["bad"] == len(garbage) + 1
    assert sink.state == "running"


@pytest.mark.parametrize(("key", "message", "options"), [
    ("toy/joints/A", {"seq": 1, "v": 1e300}, {}),                                  # beyond float32
    ("toy/joints/A", {"seq": 1, "v": [0.5, -1e39]}, {}),
    ("toy/joints/A", {"seq": 1, "v": 1e300}, {"profile": "pepperosc"}),
    ("toy/joints/A", {"seq": 1, "v": 0.5, "t": math.nan}, {"bundle": True}),        # no timetag for NaN
    ("toy/events/custom", {"kind": "custom", "count": 2**40}, {}),                  # beyond int32
    ("toy/events/custom", {"kind": "custom", "level": 1e300}, {}),
], ids=["v-1e300", "vector-1e39", "pepperosc-1e300", "bundle-t-nan", "event-int-2^40", "event-1e300"])
def test_a_value_osc_cannot_carry_does_not_stop_the_sink(net, receivers, key, message, options):
    """The forward loop must go on: the sample is refused (counted bad, or unencodable) or sent as float32 ±inf."""
    raw = receivers()
    sink = net.start(OscSink(keyed(("toy/joints/*", "toy/events/*"), targets=(raw.target,),
                                           **options), name="sound"))
    src = net.bus("toy")
    handshake(src, "toy/joints/Hello", raw)
    if "/events/" in key:
        handshake(src, "toy/events/hello", raw, {"t": time.time(), "kind": "hello"})
    src.put(key, {"t": time.time(), **message})
    src.put("toy/joints/Good", sample(2, 0.25))
    wait_for(lambda: delivered(raw, "toy/joints/Good", 0.25), timeout=2, what="a good sample after the bad value")

    def refused_or_sent_as_inf() -> bool:  # (an event and a sample come by two subscriptions: either first)
        sent = [p for a, p in messages(raw) if "ello" not in a and "Good" not in str(p) + a]
        return sink.stats["bad"] + sink.stats["unencodable"] == 1 or any(
            math.isinf(x) for p in sent for x in p if isinstance(x, float))
    wait_for(refused_or_sent_as_inf, timeout=5, what="the bad value refused, or sent as float32 inf",
             explain=lambda: f"{sink.stats}, sent {messages(raw)}")


@pytest.mark.parametrize("message", [
    {"seq": 1, "v": "15"},          # a string is not a vector of its characters
    {"seq": 1, "v": []},            # no value at all
    {"seq": 1, "v": 0.5, "t": math.nan},
    {"seq": 1, "v": 0.5, "t": math.inf},
], ids=["v-string", "v-empty", "t-nan", "t-inf"])
def test_a_malformed_sample_is_counted_not_sent(net, receivers, message):
    raw = receivers()
    sink = net.start(OscSink(keyed("toy/joints/*", targets=(raw.target,)), name="sound"))
    src = net.bus("toy")
    handshake(src, "toy/joints/Hello", raw)
    src.put("toy/joints/A", {"t": time.time(), **message})
    src.put("toy/joints/B", sample(2, 0.5))
    wait_for(lambda: ("/toy/joints/B", [0.5]) in messages(raw), what="a good sample after it")
    assert [a for a, _ in messages(raw) if a != "/toy/joints/Hello"] == ["/toy/joints/B"]
    assert sink.stats["bad"] + sink.stats["stale"] == 1
