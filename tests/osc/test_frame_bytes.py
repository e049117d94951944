"""Issue 27: a robot's frames go out from datagrams worked out once per target and joint
list (``profiles.FrameBytes``), byte for byte what the general path, one joint at a time
through ``sample`` and ``frame``, sends — for every profile and option."""

from __future__ import annotations

import struct
import threading
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus import schemas
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.osc.config import Target
from sonibus.adapters.osc.encode import NTP_OFFSET, EncodeError
from sonibus.adapters.osc.profiles import PROFILES, shape_of
from sonibus.bus import encode
from sonibus.bus.framing import frame
from sonibus.bus.keys import Key
from sonibus.bus.messages import MAX_VALUE

from ..conftest import wait_for
from .test_sink_delivery import messages

settings.register_profile("osc", deadline=None)
settings.load_profile("osc")

REFUSED = (struct.error, OverflowError, ValueError)  # what the sink's plan may raise: it then takes the general path
NAMES = st.lists(st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,11}", fullmatch=True), min_size=1, max_size=20, unique=True)
VALUE = st.one_of(st.floats(-MAX_VALUE, MAX_VALUE), st.integers(-10, 10).map(float),  # what passes the gate
                  st.floats(allow_nan=False).filter(lambda v: abs(v) > 3.5e38))      # and what OSC cannot carry
TEMPLATES = ["/{robot}/joints/{joint}", "/{key}", "/x/{name}/{section}/{robot}", "/ü/{joint}"]


@st.composite
def targets(draw: st.DrawFn) -> Target:
    if draw(st.booleans()):
        return Target(to="127.0.0.1:9", profile="pepperosc")
    return Target(to="127.0.0.1:9", address=draw(st.sampled_from(TEMPLATES)),
                  extra=tuple(draw(st.lists(st.sampled_from(["t", "seq"]), max_size=3))),
                  bundle=draw(st.booleans()), latency_ms=draw(st.floats(0, 1e4)))


def general(target: Target, sources: list[Key], values: list[float], t: float, seq: int,
            interval: float) -> list[bytes] | None:
    """What the general path sends of a frame (None: it leaves something out, as unencodable)."""
    profile = PROFILES[target.profile](target)
    try:
        if target.framed:
            samples = [(s, (v,)) for s, v in zip(sources, values, strict=True)]
            datagrams, dropped = profile.frame("pepper", t, seq, samples, interval)
            return None if dropped else datagrams
        return [profile.sample(s, (v,), t, seq) for s, v in zip(sources, values, strict=True)]
    except EncodeError:
        return None


@given(targets(), NAMES, st.data(), st.floats(0, 2**32 - NTP_OFFSET - 1), st.integers(0, 2**63 - 1),
       st.floats(0, 1e3))
@settings(max_examples=300)
def test_a_frame_s_precomputed_bytes_are_the_general_path_s(target, names, data, t, seq, interval):
    values = data.draw(st.lists(VALUE, min_size=len(names), max_size=len(names)))
    sources = [Key.parse(f"pepper/joints/{name}") for name in names]
    compiled = PROFILES[target.profile](target).compile(sources)
    assert compiled is not None
    expected = general(target, sources, values, t, seq, interval)
    if expected is None:  # a value OSC cannot carry: the sink's plan gives up, the general path leaves it out
        with pytest.raises(REFUSED):
            compiled.render(t, seq, values, interval)
    else:
        assert compiled.render(t, seq, values, interval) == expected


def test_one_plan_renders_frame_after_frame_as_the_general_path_whatever_came_before():
    """A bundle's plan keeps its arguments between frames (issue 35: packed in one call, its
    values put in place by slice): each frame is still the general path's bytes, after a
    frame of other values, of values OSC cannot carry (refused), of too few values."""
    names = ["HeadYaw", "HeadPitch", "LHand"]
    sources = [Key.parse(f"pepper/joints/{name}") for name in names]
    for extra in ((), ("t", "seq"), ("seq", "t", "seq")):
        target = Target(to="127.0.0.1:9", bundle=True, extra=extra, latency_ms=25.0)
        compiled = PROFILES["sonibus"](target).compile(sources)
        assert compiled is not None
        frames = [(1.7e9 + 0.01 * n, n, [0.1 * n, -0.5, 2.0 + n]) for n in range(6)]
        frames.insert(2, (1.7e9, 99, [0.0, 1e39, 0.0]))  # beyond float32: refused
        frames.insert(4, (1.7e9, 98, [0.0, 1.0]))        # a value short: refused
        for t, seq, values in frames:
            expected = general(target, sources, values, t, seq, 0.0) if len(values) == len(names) else None
            if expected is None:
                with pytest.raises(REFUSED):
                    compiled.render(t, seq, values)
            else:
                assert compiled.render(t, seq, values) == expected, (extra, seq)


# -- the sink, both ways -------------------------------------------------------------------------

NAMES_OF_TOY = ["A", "B", "C", "D", "Unranged"]
RANGES = [("A", -2.0, 2.0), ("B", 0.0, 10.0), ("C", -1.0, 1.0), ("D", 5.0, 5.0)]  # D: an empty range
CONFIGS = {
    "messages": {},
    "t and seq": {"extra": ("t", "seq")},
    "bundle": {"bundle": True, "latency_ms": 25.0, "extra": ("seq",)},
    "pepperosc": {"profile": "pepperosc"},
    "normalized": {"values": "normalized", "extra": ("seq",)},
    "normalized bundle": {"values": "normalized", "bundle": True, "extra": ("seq",)},
}


def toy_info() -> dict:
    joints = [{"name": name, "unit": "rad", "min": low, "max": high, "max_velocity": 1.0} for name, low, high in RANGES]
    return {"robot": "toy", "model": "toy", "rate_hz": 100.0, "behaviors": [], "postures": [], "adapter": "test",
            "schema_version": schemas.VERSION, "owner": {"host": "h", "node": "toy"}, "joints": joints}


def seqs(receiver, first: int) -> list[bytes]:
    """The datagrams whose messages all carry a seq (their last argument) from ``first`` on."""
    from pythonosc.osc_packet import OscPacket
    return [d for d in receiver.data() if all(m.message.params[-1] >= first for m in OscPacket(d).messages)]


@pytest.mark.parametrize("options", CONFIGS.values(), ids=CONFIGS.keys())
def test_the_sink_sends_the_same_bytes_through_its_plans_as_through_the_general_path(net, receivers, options):
    """Two sinks take the same frames in their queues, as their subscription puts them: one
    through its plans, one made to take the general path for every frame."""
    queryable = net.bus("toy").serve("toy/info", lambda query: query.reply(query.key_expr, encode(toy_info())))
    planned, general_path = receivers(), receivers()
    config = {"subscribe": "toy/joints/*", "max_age_ms": 0, **options}
    fast = net.start(OscSink(OscSinkConfig(targets=(planned.target,), **config), name="planned"))
    slow = net.start(OscSink(OscSinkConfig(targets=(general_path.target,), **config), name="general"))
    slow._planned = lambda *args: False  # (every frame through sample/frame, one joint at a time)
    took: list[bool] = []
    plan = fast._planned
    fast._planned = lambda *args: took.append(plan(*args)) or took[-1]
    base = time.time()

    def put(seq: int) -> None:
        """One frame into both queues, taken by both before the next (frames put at once are a burst)."""
        values = [0.5 * seq - 3.0, 2.5 * seq, -4.0 + seq, 5.0 + 0.1 * seq, 1e5 - seq]
        payload = encode(frame(base + 1e-4 * seq, seq, NAMES_OF_TOY, values))
        before = [sink.stats["received"] for sink in (fast, slow)]
        for sink in (fast, slow):
            sink._queue.put(("toy/frame", payload))
        wait_for(lambda: fast.stats["received"] > before[0] and slow.stats["received"] > before[1],
                 what=f"frame {seq} taken by both sinks")

    first = 0
    if options.get("values") == "normalized":  # the robot's info, asked for at its first frame, in both sinks
        wait_for(lambda: put(first) or (planned.data() and general_path.data()), what="both sinks knowing toy's ranges")
        first = 1_000
    for seq in range(first, first + 8):
        put(seq)
    per_frame = 1 if options.get("bundle") else len(NAMES_OF_TOY) + (options.get("profile") == "pepperosc")
    if first:
        wait_for(lambda: len(seqs(planned, first)) == len(seqs(general_path, first)) == 8 * per_frame,
                 what="the eight frames at both targets")
        assert seqs(planned, first) == seqs(general_path, first)
    else:
        wait_for(lambda: len(planned.data()) == len(general_path.data()) == 8 * per_frame,
                 what="the eight frames at both targets")
        assert planned.data() == general_path.data()
        assert fast.stats["sent"] == slow.stats["sent"]  # (counted once a frame, or once a datagram)
    assert any(took), "the plans were never used"
    assert fast.stats["unencodable"] == slow.stats["unencodable"] == 0
    if options.get("values") == "normalized":
        values = [p for a, p in messages(planned) if a == "/toy/joints/Unranged"]
        assert values[-1][0] == 1e5 - (first + 7)  # a joint the info has no range for goes raw
    queryable.undeclare()


def test_made_up_joint_lists_do_not_grow_the_plans(net, receivers):
    """Joint lists come from the network: a sink keeps at most ``MAX_PLANS`` lanes (a plan for
    each target), however many robots and lists are made up, and still sends each frame (through
    a new plan)."""
    from sonibus.adapters.osc import link as osc_link
    receiver = receivers()
    sink = net.start(OscSink(OscSinkConfig(targets=(receiver.target,), subscribe="*/joints/*", max_age_ms=0),
                             name="plans"))
    for n in range(osc_link.MAX_PLANS + 100):
        payload = encode(frame(time.time(), n, ["A", f"Made{n}"], [0.25, 0.5]))
        sink._direct(f"robot{n % 7}/frame", payload)  # (as its subscription's callback does)
        assert len(sink._lanes) <= osc_link.MAX_PLANS
    assert len(sink._lanes) > 50, "the plans were never used"

    def last_sent() -> bool:  # (again until one arrives: UDP may drop one of a thousand sent at once)
        sink._direct("robot0/frame", encode(frame(time.time(), 10 ** 6, ["A", "Last"], [0.25, 0.5])))
        return any(a == "/robot0/joints/Last" for a, _ in messages(receiver))
    wait_for(last_sent, what="a frame at the target after them")
    assert len(sink._lanes) <= osc_link.MAX_PLANS


def test_a_frame_never_waits_on_zenohs_thread_for_the_forward_worker(net, receivers):
    """Frames are taken on the subscription's callback thread, which serves every
    subscription and query of the session: while the sink's worker holds its state (a
    batch of a burst can take seconds), a frame goes into the queue instead of waiting."""
    receiver = receivers()
    sink = net.start(OscSink(OscSinkConfig(targets=(receiver.target,), subscribe="toy/joints/*", max_age_ms=0),
                             name="busy"))
    robot = net.bus("toy")
    seq = iter(range(10 ** 6))

    def queued() -> bool:  # (put again until the sessions see each other)
        robot.put("toy/frame", frame(time.time(), next(seq), ["A"], [0.25]))
        deadline = time.monotonic() + 0.2
        while time.monotonic() < deadline and not len(sink._queue):
            time.sleep(0.01)
        return len(sink._queue) > 0
    with sink._state:  # (as the forward worker does while it takes a batch)
        sink._working = True
        try:
            wait_for(queued, what="a frame in the queue while the worker is busy")
        finally:
            sink._working = False
    wait_for(lambda: any(a == "/toy/joints/A" for a, _ in messages(receiver)), what="the frame at the target")


def test_a_frame_waits_for_another_taken_where_it_arrived_not_for_the_queue(net, receivers, monkeypatch):
    """Issue 35: a derived frame and its robot's frame arrive together on two of Zenoh's
    threads; the one that finds the state held by the other's (quick) take waits for it and is
    taken there too, not handed to the queue (a wake-up of the worker each time)."""
    from sonibus.adapters.osc import sink as osc_sink
    monkeypatch.setattr(osc_sink, "DIRECT_WAIT_S", 30.0)  # (whatever the machine's load)
    receiver = receivers()
    sink = net.start(OscSink(OscSinkConfig(targets=(receiver.target,), subscribe="toy/joints/*", max_age_ms=0),
                             name="two"))
    held, release = threading.Event(), threading.Event()

    def other_take() -> None:  # (as another subscription's callback holds the state while it takes its frame)
        with sink._state:
            held.set()
            release.wait(0.05)
    other = threading.Thread(target=other_take)
    other.start()
    held.wait(10)
    taken = sink._direct("toy/frame", encode(frame(time.time(), 1, ["A"], [0.25])))
    release.set()
    other.join(10)
    assert taken and not len(sink._queue)
    wait_for(lambda: any(a == "/toy/joints/A" for a, _ in messages(receiver)), what="the frame at the target")


def test_a_frame_that_arrives_while_the_sink_subscribes_is_queued_not_a_failure(net, receivers, monkeypatch):
    """A robot already streaming: its first frame can reach ``_direct`` on Zenoh's thread
    while ``Streams`` is still declaring the sink's other subscriptions, before the sink
    holds it — ``make demo`` once failed the sink there (``'OscSink' object has no
    attribute '_streams'``). Such a frame goes into the queue and out to the target."""
    from sonibus.adapters.osc import sink as osc_sink
    real = osc_sink.Streams

    class Subscribing(real):  # a frame comes in at the end of subscribing, as it can from a live robot
        def __init__(self, bus, patterns, queue, **options):
            super().__init__(bus, patterns, queue, **options)
            frame_now = encode(frame(time.time(), 1, ["A"], [0.25]))
            assert options["direct"]("toy/frame", frame_now) is False  # (not taken there: queued)
            queue.put(("toy/frame", frame_now))

    monkeypatch.setattr(osc_sink, "Streams", Subscribing)
    receiver = receivers()
    sink = net.start(OscSink(OscSinkConfig(targets=(receiver.target,), subscribe="toy/joints/*", max_age_ms=0),
                             name="early"))
    wait_for(lambda: any(a == "/toy/joints/A" for a, _ in messages(receiver)), what="the early frame at the target")
    assert sink.stats["errors"] == 0 and not sink.failure and sink.state == "running"


# -- derived frames (issue 35) ------------------------------------------------------------------

DERIVED_NAMES = st.lists(st.from_regex(r"[a-z]{1,6}/[A-Za-z0-9_]{1,8}", fullmatch=True), min_size=1, max_size=12,
                         unique=True)
DERIVED_TEMPLATES = ["/{robot}/derived/{feature}/{name}", "/{key}", "/d/{name}/{section}", "/ü/{feature}"]
NUMBER = st.one_of(VALUE, st.integers(-10, 10))  # (ints pass the gate in a derived frame)
DERIVED_VALUE = st.one_of(NUMBER, st.lists(NUMBER, min_size=1, max_size=4))


def general_derived(target: Target, sources: list[Key], values: list, t: float, seq: int) -> list[bytes] | None:
    """What the general path sends of a derived frame's values, one at a time through ``sample``
    (None: it leaves one out, as unencodable)."""
    profile = PROFILES["sonibus"](target)
    try:
        return [profile.sample(s, tuple(map(float, v)) if isinstance(v, list) else (float(v),), t, seq)
                for s, v in zip(sources, values, strict=True)]
    except EncodeError:
        return None


@given(DERIVED_NAMES, st.data(), st.floats(0, 2**32 - NTP_OFFSET - 1),
       st.integers(0, 2**63 - 1), st.sampled_from(DERIVED_TEMPLATES),
       st.lists(st.sampled_from(["t", "seq"]), max_size=3))
@settings(max_examples=300)
def test_a_derived_frame_s_precomputed_bytes_are_the_general_path_s(names, data, t, seq, template, extra):
    """``DerivedBytes``: a message per value, byte for byte what ``sample`` sends of each, for
    the shape it was planned for; a value of another shape (a number for a list, a list of other
    size) or one OSC cannot carry raises, and the sink then takes the general path."""
    target = Target(to="127.0.0.1:9", derived_address=template, extra=tuple(extra))
    sources = [Key.parse(f"pepper/derived/{name}") for name in names]
    planned = data.draw(st.lists(DERIVED_VALUE, min_size=len(names), max_size=len(names)))
    compiled = PROFILES["sonibus"](target).compile_derived(sources, shape_of(planned))
    assert compiled is not None and compiled.shape == shape_of(planned)
    for values in (planned, data.draw(st.lists(DERIVED_VALUE, min_size=len(names), max_size=len(names)))):
        expected = general_derived(target, sources, values, t, seq)
        if expected is None or shape_of(values) != compiled.shape:
            with pytest.raises((*REFUSED, TypeError)):
                compiled.render(t, seq, values)
        else:
            assert compiled.render(t, seq, values) == expected
