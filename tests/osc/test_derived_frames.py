"""Issue 35: derived values come as one derived frame per robot and tick (``<robot>/derived``);
the OSC sink sends what it sent when each came on its own key, byte for byte — per message,
with ``t``/``seq``, normalized by ``<robot>/info/derived``'s ranges, in bundles with the
joints of their frame, and PepperOSC's profile. Two sinks take the same values in their
queues, as their subscriptions put them: one per key (the format before), one in frames."""

from __future__ import annotations

import time

import pytest

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import encode, keys
from sonibus.bus.framing import derived_frame, derived_samples, frame

from ..conftest import wait_for
from .test_frame_bytes import CONFIGS, toy_info

DERIVED = ["qom/Body", "hand/R", "velocity/A", "hand_speed/R"]
RANGES = {"qom/Body": (0.0, 4.0), "hand/R": (-1.0, 1.0), "velocity/A": (-2.0, 2.0)}  # hand_speed/R: none


def derived_info() -> dict:
    return {"robot": "toy", "processor": {"host": "h", "node": "features"},
            "derived": [{"name": name, "key": f"toy/derived/{name}", "unit": "x", "size": 3 if "hand/" in name else 1,
                         **({"min": RANGES[name][0], "max": RANGES[name][1]} if name in RANGES else {})}
                        for name in DERIVED]}


@pytest.mark.parametrize("options", CONFIGS.values(), ids=CONFIGS.keys())
def test_a_derived_frame_goes_out_as_its_values_did_on_their_own_keys(net, receivers, options):
    toy = net.bus("toy")
    served = [toy.serve(key, lambda query, key=key, info=info: query.reply(key, encode(info)))
              for key, info in (("toy/info", toy_info()), ("toy/info/derived", derived_info()))]
    per_key, framed = receivers(), receivers()
    config = {"subscribe": ("toy/joints/*", "toy/derived/**"), "max_age_ms": 0, **options}
    before = net.start(OscSink(OscSinkConfig(targets=(per_key.target,), **config), name="per-key"))
    after = net.start(OscSink(OscSinkConfig(targets=(framed.target,), **config), name="framed"))
    base = time.time()

    def put(seq: int) -> None:
        """One joint frame and its derived values into both queues, taken by both before the next."""
        t = base + 1e-4 * seq
        joints = encode(frame(t, seq, ["A", "B", "C", "D", "Unranged"], [0.1 * seq, 1.0, -0.5, 5.0, 3.0]))
        values = derived_frame(t, seq, DERIVED, [0.5 * seq, [0.1 * seq, -0.2, 2.0], -1.5 + seq, 0.25])
        was = [sink.stats["received"] for sink in (before, after)]
        for sink in (before, after):
            sink._queue.put(("toy/frame", joints))
        for name, sample in derived_samples(values):
            before._queue.put((keys.derived_frame("toy") + "/" + name, encode(sample)))
        after._queue.put(("toy/derived", encode(values)))
        wait_for(lambda: before.stats["received"] >= was[0] + 9 and after.stats["received"] >= was[1] + 9,
                 what=f"frame {seq} taken by both sinks")

    first = 0
    if options.get("values") == "normalized":  # the ranges, asked for at the first message, in both sinks
        wait_for(lambda: put(first) or all(sink._ranges.describes("toy", "qom/Body") for sink in (before, after)),
                 what="both sinks knowing toy's derived ranges")
        first = 1_000
    for seq in range(first, first + 8):
        put(seq)
    wait_for(lambda: len(per_key.data()) >= 8 and len(per_key.data()) == len(framed.data()),
             what="the frames at both targets")
    sent = per_key.data()
    assert framed.data() == sent
    if options.get("profile") != "pepperosc":  # (PepperOSC's profile sends joints only)
        assert any(b"/toy/derived/hand/R" in d for d in sent)
    for served_ in served:
        served_.undeclare()


def test_a_derived_frame_is_taken_where_it_arrives_not_through_the_queue(net, receivers):
    """Derived frames, one a tick beside the robot's, are taken on the subscription's
    callback thread as the robot's frames are (a thread hand-off a frame less: the worker's
    wake-up cost the show's OSC node more than the frame's work, docs/performance.md)."""
    receiver = receivers()
    sink = net.start(OscSink(OscSinkConfig(targets=(receiver.target,), subscribe="toy/derived/**", max_age_ms=0,
                                           values="raw"), name="derived"))
    queued: list[str] = []
    put = sink._queue.put

    def spy(item, *args, **kwargs):  # (what the subscriptions put into the sink's queue)
        queued.append(item[0])
        return put(item, *args, **kwargs)

    sink._queue.put = spy
    robot = net.bus("toy")
    seq = iter(range(10 ** 6))

    def tick() -> None:
        robot.put("toy/derived", derived_frame(time.time(), next(seq), ["qom/Body"], [0.5]))
        time.sleep(0.02)  # (a tick's spacing: not paced)

    wait_for(lambda: tick() or receiver.data(), what="the sessions to see each other")
    queued.clear()
    sent = len(receiver.data())
    for _ in range(10):
        tick()
    wait_for(lambda: len(receiver.data()) >= sent + 10, what="ten derived frames at the target")
    assert queued.count("toy/derived") <= 1, queued  # (one may meet the worker holding the state)


@pytest.mark.parametrize("extra", [(), ("t", "seq")], ids=["plain", "t and seq"])
def test_derived_frames_whose_values_change_shape_go_out_as_the_general_path_sends_them(net, receivers, extra):
    """Issue 35: a target of plain messages sends a derived frame from datagrams worked out once
    for its values' shape (``profiles.DerivedBytes``); a frame whose values change shape (a
    vector shrinks, a number comes where a vector was) or holds ints goes out byte for byte as
    the general path sends it, value by value. (A value OSC cannot carry, beyond float32, the
    gate refuses first: past ±1e6.)"""
    planned, general_path = receivers(), receivers()
    config = {"subscribe": "toy/derived/**", "max_age_ms": 0, "extra": extra}
    fast = net.start(OscSink(OscSinkConfig(targets=(planned.target,), **config), name="planned"))
    slow = net.start(OscSink(OscSinkConfig(targets=(general_path.target,), **config), name="general"))
    slow._planned_derived = lambda link, parts: False  # (every value through sample, one at a time)
    took: list[bool] = []
    plan = fast._planned_derived
    fast._planned_derived = lambda link, parts: took.append(plan(link, parts)) or took[-1]
    names, base = ["qom/Body", "hand/R", "velocity/A"], time.time()
    values = [[0.5, [0.1, 0.2, 0.3], -1.0], [0.6, [0.1, 0.2, 0.3], -1.1],  # planned for (1, 3, 1)
              [0.7, [0.1, 0.2], -1.2], [0.8, [0.1, 0.2], -1.3],           # the vector shorter: planned again
              [[0.9], 2, 3],                                              # a vector of one, ints
              [1.1, [0.4, 0.5, 0.6], -1.4]]
    for seq, v in enumerate(values):
        payload = encode(derived_frame(base + 1e-4 * seq, seq, names, v))
        was = [sink.stats["received"] for sink in (fast, slow)]
        for sink in (fast, slow):
            sink._queue.put(("toy/derived", payload))
        wait_for(lambda was=was: fast.stats["received"] > was[0] and slow.stats["received"] > was[1],
                 what=f"derived frame {seq} taken by both sinks")
    wait_for(lambda: len(planned.data()) == len(general_path.data()) == 3 * len(values),
             what="every value at both targets")
    assert planned.data() == general_path.data()
    assert fast.stats["sent"] == slow.stats["sent"] and fast.stats["unencodable"] == slow.stats["unencodable"] == 0
    assert took == [True] * len(values)  # (a plan for every shape: planned again when it changed)
