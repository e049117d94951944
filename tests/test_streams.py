"""The frame key beside the per-joint keys: what a robot owner publishes, and what
``bus.streams`` subscribes to for a sink's patterns."""

from __future__ import annotations

import sys
import threading
import time

import pytest

from sonibus import schemas
from sonibus.bus import codec, framing, streams
from sonibus.bus.plan import Plan, plan
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Incoming, Selection, Streams

from .conftest import wait_for

REST = ("derived", "events", "info", "cmd")  # the sections besides frames and joints a broad pattern takes
# (derived keys under one chunk at least: ``pepper/derived`` itself, the derived frame, comes on its own)
REST_OF_PEPPER = tuple(f"pepper/{s}/*/**" if s == "derived" else f"pepper/{s}/**" for s in REST)


@pytest.mark.parametrize(("patterns", "per_joint_keys", "expected"), [
    (["*/joints/*"], False, Plan(frames=("*/frame",))),
    (["pepper/joints/R*", "nao/joints/*"], False, Plan(frames=("pepper/frame", "nao/frame"))),
    (["*/joints/*", "*/derived/**", "*/events/*"], False,
     Plan(frames=("*/frame",), keys=("*/derived/*/**", "*/events/*"), derived=("*/derived",))),
    # a pattern that does not name audio (or stats) is narrowed to the sections it may take: it does
    # not subscribe to the microphones (their owner publishes them only while someone listens)
    (["**"], False, Plan(frames=("*/frame",), keys=("*/derived/*/**", "*/events/**", "*/info/**", "*/cmd/**"),
                         broad=("*/joints/**",), derived=("*/derived",))),
    (["pepper/**"], False, Plan(frames=("pepper/frame",), keys=REST_OF_PEPPER, broad=("pepper/joints/**",),
                                derived=("pepper/derived",))),
    (["**/HeadYaw"], False, Plan(frames=("*/frame",), keys=tuple(f"*/{s}/**/HeadYaw" for s in REST),
                                 broad=("*/joints/**/HeadYaw",), derived=("*/derived",))),
    (["pepper/joints/R*", "pepper/**"], True, Plan(keys=("pepper/joints/R$*", "pepper/joints/**", *REST_OF_PEPPER),
                                                   derived=("pepper/derived",))),
    (["*/joints/HeadYaw", "pepper/joints/R*"], False, Plan(frames=("*/frame",))),  # overlapping: one frame key
    (["pepper/**", "*/joints/*"], False, Plan(frames=("*/frame",), keys=REST_OF_PEPPER, broad=("pepper/joints/**",),
                                              derived=("pepper/derived",))),
    # derived values: served from the derived frames of the robots named (and from their own keys)
    (["pepper/derived/qom/*", "nao/derived/**"], False,
     Plan(keys=("pepper/derived/qom/*", "nao/derived/*/**"), derived=("pepper/derived", "nao/derived"))),
    (["**/audio/mic"], False, Plan(keys=("**/audio/mic",))),  # audio named after a leading **: kept
    (["pepper/audio/mic", "pepper/*/mic"], False,
     Plan(keys=("pepper/audio/mic", *(f"pepper/{s}/mic" for s in REST)),
          frames=("pepper/frame",))),
])
def test_joint_patterns_are_served_from_frames(patterns, per_joint_keys, expected):
    assert plan(patterns, per_joint_keys) == expected


def test_a_frame_holds_the_values_of_the_joint_samples(net):
    """Late subscribers of joint keys are served too (the owner puts them only while someone listens)."""
    watcher = net.bus("watcher")
    frames: dict[int, dict] = {}
    joints: dict[int, dict[str, dict]] = {}
    lock = threading.Lock()

    def take_frame(sample) -> None:
        message = codec.decode(sample.payload.to_bytes())
        with lock:
            frames[message["seq"]] = message

    def take_joint(sample) -> None:
        message = codec.decode(sample.payload.to_bytes())
        with lock:
            joints.setdefault(message["seq"], {})[str(sample.key_expr).rsplit("/", 1)[1]] = message

    subscribers = [watcher.session.declare_subscriber("pepper/frame", take_frame)]
    robot = net.sim("pepper", rate_hz=50)
    wait_for(lambda: len(frames) >= 5, what="five frames")
    subscribers.append(watcher.session.declare_subscriber("pepper/joints/*", take_joint))
    complete = lambda: [s for s, j in list(joints.items()) if len(j) == 17 and s in frames]  # noqa: E731
    wait_for(lambda: len(complete()) >= 5, what="five frames also as joint samples")
    with lock:
        for seq in complete():
            frame = frames[seq]
            schemas.validate("frame", frame)
            assert frame["names"] == list(robot.model.joint_names)
            for name, value in zip(frame["names"], frame["v"], strict=True):
                assert joints[seq][name] == {"t": frame["t"], "seq": seq, "v": value}
    for subscriber in subscribers:
        subscriber.undeclare()


def test_a_broad_pattern_takes_each_joint_once(net):
    """``pepper/**`` selects joint and frame keys; the joints come from the frames only."""
    sink = net.bus("sink")
    queue = SampleQueue(100_000)
    streams = Streams(sink, ["pepper/**"], queue)
    net.sim("pepper", rate_hz=50)
    watcher = net.bus("watcher").session.declare_subscriber("pepper/joints/*", lambda sample: None)  # joints put too
    taken: list[Incoming] = []
    wait_for(lambda: taken.extend(streams.incoming(*item) for item in queue.drain(0.05)) or len(taken) >= 60,
             what="60 messages")
    seqs = [m.seq for m in taken if m.source.section == "frame"]
    assert seqs and len(seqs) == len(set(seqs))
    assert all(m.source.section in ("frame", "events") for m in taken), {m.source.key for m in taken}
    assert all(len(m.joints) == 17 for m in taken if m.source.section == "frame")
    watcher.undeclare()
    streams.undeclare()


def test_derived_frames_come_once_as_the_samples_of_the_keys_the_patterns_select(net):
    """Issue 35: overlapping patterns of derived keys share one subscription to the derived
    frames, which each come once, as the samples of the selected keys; a value put on its own
    key (a map node, ``per_key = true``) still comes on it."""
    sink = net.bus("sink")
    queue = SampleQueue(100_000)
    streams = Streams(sink, ["pepper/derived/qom/*", "*/derived/hand/**", "pepper/events/*"], queue, pace=False)
    robot = net.bus("robot")
    taken: list[Incoming] = []
    seq = iter(range(10**6))

    def put() -> bool:
        frame = framing.derived_frame(time.time(), next(seq), ["qom/Body", "hand/R", "velocity/HeadYaw"],
                                       [0.5, [0.1, 0.2, 0.3], 1.5])
        robot.put("pepper/derived", frame)
        robot.put("pepper/derived/qom/Head", {"t": time.time(), "seq": 7, "v": 0.25})
        taken.extend(streams.incoming(*item) for item in queue.drain(0.05))
        return len([m for m in taken if m.parts]) >= 3 and any(m.source.name == "Head" for m in taken)
    wait_for(put, what="derived frames and a derived sample")
    framed = [m for m in taken if m.parts is not None]
    assert len(framed) == len({m.seq for m in framed})  # each once
    frame = framed[0].message
    parts = framed[0].joints
    assert [(p.source.key, p.values, p.message) for p in parts] == [
        ("pepper/derived/qom/Body", (0.5,), {"t": frame["t"], "seq": frame["seq"], "v": 0.5}),
        ("pepper/derived/hand/R", (0.1, 0.2, 0.3), {"t": frame["t"], "seq": frame["seq"], "v": [0.1, 0.2, 0.3]})]
    assert parts[1].source.feature == "hand" and parts[1].source.name == "R"
    streams.undeclare()


def test_a_payload_over_the_size_limit_is_queued_as_its_size_only_and_refused_by_the_gate(net):
    """A flood of huge frames filled a sink's memory (+251 MB in the soak) before the gate
    refused them by their size: the subscription keeps only the size of such a payload."""
    sink, robot = net.bus("sink"), net.bus("robot")
    limit = sink.limits.max_payload
    subscriber, queue = sink.subscribe("pepper/**")
    try:
        huge = {"t": 1.0, "seq": 1, "names": ["J"], "v": [0.0], "pad": "x" * (4 * limit)}
        info = {"robot": "pepper", "pad": "x" * (2 * limit)}  # a robot's info may be larger: kept
        items: dict[str, object] = {}

        def both_arrived() -> bool:  # (sent again until the subscription has reached the robot's session)
            robot.put("pepper/frame", huge)
            robot.put("pepper/info", info)
            items.update(queue.drain(timeout=0.2))
            return len(items) == 2
        wait_for(both_arrived, what="both payloads at the sink")
        size = len(codec.encode(huge))
        assert isinstance(items["pepper/frame"], codec.Oversize) and len(items["pepper/frame"]) == size
        assert items["pepper/info"] == codec.encode(info)
        counted: list[tuple[str, int]] = []
        warned: list[str] = []
        assert Selection(["pepper/joints/*"], sink.limits).take(
            "pepper/frame", items["pepper/frame"], lambda k, n: counted.append((k, n)),
            lambda k, m: warned.append(m)) is None
        assert ("bad", 1) in counted
        assert warned == [f"message on 'pepper/frame' refused: payload of {size} bytes is over the limit of {limit}"]
        with pytest.raises(codec.DecodeError, match="over the size limit"):
            codec.decode(items["pepper/frame"])
    finally:
        subscriber.undeclare()


def test_each_frame_gets_the_selection_of_its_own_joint_list():
    """A sink remembers what it takes of a robot's last joint list: a robot whose list changes
    (or a node that changes a message's list afterwards) still gets each frame's own joints."""
    selection = Selection(["*/joints/Head*"])
    lists = [["HeadYaw", "LHand", "HeadPitch"], ["LHand", "HeadPitch"], ["HeadYaw", "LHand", "HeadPitch"]]
    for robot in ("pepper", "nao"):
        for seq, names in enumerate(lists):
            values = [float(i) for i in range(len(names))]
            frame = codec.encode({"t": 1.5, "seq": seq, "names": names, "v": values})
            taken = selection.incoming(f"{robot}/frame", frame)
            assert [(s.source.key, s.values) for s in taken.samples] == [
                (f"{robot}/joints/{n}", (v,)) for n, v in zip(names, values, strict=True) if n.startswith("Head")]
            taken.message["names"][:] = lists[(seq + 1) % len(lists)]  # (the one remembered is a copy)


def test_made_up_robots_and_joint_lists_do_not_grow_a_sinks_tables():
    """Robot names and joint lists come from the network: the selections a sink keeps
    per joint list and per robot, and its gate's joint lists, stay within their bounds
    however many are made up (the fuzz show sends frames of made-up lists and robots)."""
    selection = Selection(["*/joints/*"])
    extra = streams.MAX_FRAMES + 200
    for n in range(extra):
        names = ["HeadYaw", f"Made{n}"]
        taken = selection.incoming(f"robot{n}/frame", codec.encode({"t": 1.5, "seq": n, "names": names,
                                                                   "v": [0.1, 0.2]}))
        assert [s.source.key for s in taken.samples] == [f"robot{n}/joints/HeadYaw", f"robot{n}/joints/Made{n}"]
    assert len(selection._frames) <= streams.MAX_FRAMES and len(selection._last) <= streams.MAX_FRAMES
    assert len(selection.gate._last_names) <= selection.gate.MAX_KNOWN
    assert len(selection.gate._known_names) <= selection.gate.MAX_KNOWN
    assert len(selection._parsed) <= streams.MAX_KEYS


def test_what_waits_for_its_turn_is_bounded_by_the_queue(net):
    """Samples held for their turn after a stall (skip, never burst) are kept by key, and keys
    come from the network: no more are kept than the queue holds, the one held longest
    going first in both (counted ``dropped`` by the queue)."""
    queue = SampleQueue(4)
    paced = Streams(net.bus("held"), ["*/derived/**"], queue)
    counted: dict[str, int] = {}

    def take(key: str, seq: int, t: float) -> None:
        paced.take(key, codec.encode({"t": t, "seq": seq, "v": 0.5}), lambda kind, n: counted.update(
            {kind: counted.get(kind, 0) + n}), lambda kind, text: None)
    keys = [f"robot{n}/derived/qom/Body" for n in range(10)]
    t0 = time.time() - 1.0
    for seq in range(5):  # each key's period learnt: 20 ms
        for key in keys:
            take(key, seq, t0 + 0.02 * seq)
    time.sleep(0.3)  # a stall: longer than pacing.STALL_S
    for key in keys:
        take(key, 5, t0 + 0.1)  # goes
        take(key, 6, t0 + 0.12)  # held for its turn
    assert len(paced._held) <= queue.maxlen and len(queue) <= queue.maxlen
    assert queue.dropped == len(keys) - queue.maxlen
    assert set(paced._held) == set(keys[-queue.maxlen:])
    paced.undeclare()


def test_a_sample_on_a_robots_joints_key_alone_is_refused_not_taken_for_a_derived_frame():
    """``pepper/joints`` (no joint named) reaches a sink of ``pepper/**`` (``**`` matches no chunk too):
    it was taken for a derived frame, and the KeyError of its missing names ended the sink's worker."""
    counted, warned = {}, []
    selection = Selection(["pepper/**"])
    taken = selection.take("pepper/joints", codec.encode({"t": time.time(), "seq": 1, "v": 0.5}),
                           lambda what, n: counted.update({what: counted.get(what, 0) + n}),
                           lambda what, text: warned.append(text))
    assert taken is None and counted == {"received": 1, "bad": 1}
    assert warned == ["message on 'pepper/joints' refused: pepper/joints names no joint: "
                      "a joint's sample goes on <robot>/joints/<Joint>"]


def test_two_threads_taking_one_robots_frames_with_two_joint_lists_each_get_their_own_joints():
    """One ``Selection`` (a sink takes frames on the callback thread and on its worker) given one
    robot's frames whose joint list changes every frame: each frame's values are those of its own
    names, never picked by the other list's selection (what is kept per names is one snapshot,
    read once a frame)."""
    selection = Selection(["pepper/joints/HeadYaw"])
    t = time.time() - 1
    payloads = [codec.encode(framing.frame(t, 0, ["HeadYaw", "LHand"], [1.0, 2.0])),
                codec.encode(framing.frame(t, 1, ["LHand", "HeadYaw", "RHand"], [2.0, 1.0, 3.0]))]
    wrong: list[tuple[str, ...]] = []

    def take(first: int) -> None:
        for i in range(4000):
            message = selection.incoming("pepper/frame", payloads[(first + i) % 2])
            if message.values != (1.0,) or [s.key for s in message.selected.sources] != ["pepper/joints/HeadYaw"]:
                wrong.append(message.values)

    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # (the threads switch as often as they can)
    try:
        threads = [threading.Thread(target=take, args=(first,)) for first in (0, 1)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    finally:
        sys.setswitchinterval(switch)
    assert wrong == []


def test_a_robots_next_frames_find_their_selection_by_the_gates_names_without_comparing(monkeypatch):
    """The gate compares a frame's names with the robot's last frame's and gives the same tuple when
    they are; the selection is then found by that tuple's identity: no name compared again."""
    selection = Selection(["pepper/joints/Head*"])
    t = time.time() - 1
    frames = [codec.encode(framing.frame(t + seq, seq, ["HeadYaw", "LHand"], [0.1 * seq, 0.5])) for seq in range(5)]
    first = selection.incoming("pepper/frame", frames[0])
    worked_out = []
    chosen = Selection._chosen
    monkeypatch.setattr(Selection, "_chosen", lambda *args: worked_out.append(args[1]) or chosen(*args))
    taken = [selection.incoming("pepper/frame", payload) for payload in frames[1:]]
    assert worked_out == []
    assert all(m.selected is first.selected for m in taken)
    assert [m.values for m in taken] == [(0.1 * s,) for s in range(1, 5)]
    other = selection.incoming("pepper/frame", codec.encode(framing.frame(t, 9, ["LHand", "HeadPitch"], [0.5, 0.7])))
    assert worked_out == ["pepper"] and other.values == (0.7,) and other.selected is not first.selected


def test_a_derived_frames_parts_are_made_only_when_a_sink_looks_at_them():
    """``Incoming.parts`` knows its length at once (what ``take`` counts); its samples are made
    the first time they are read, once, the same as each value's key would carry."""
    selection = Selection(["pepper/derived/qom/*"])
    t = time.time() - 1
    payload = codec.encode(framing.derived_frame(t, 3, ["qom/all", "hand/R", "qom/arm"], [0.2, [0.1, 0.3], 0.4]))
    message = selection.incoming("pepper/derived", payload)
    assert len(message.parts) == 2 and message.parts and message.parts._made is None  # (none made yet)
    assert [(p.source.key, p.message, p.values) for p in message.parts] == [
        ("pepper/derived/qom/all", {"t": t, "seq": 3, "v": 0.2}, (0.2,)),
        ("pepper/derived/qom/arm", {"t": t, "seq": 3, "v": 0.4}, (0.4,))]
    assert message.parts[1] is message.parts._made[1]  # (made once)
