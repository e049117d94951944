"""The nodes of one process check a frame once (``bus/verdicts.py``, issue 35): each still
gets a message of its own and the verdict its own limits give."""

from __future__ import annotations

import random
import threading
import time

import pytest
import zenoh

from sonibus.bus import codec, framing, messages
from sonibus.bus.keys import Key
from sonibus.bus.messages import BadMessage, Limits
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Selection, Streams
from sonibus.bus.verdicts import Verdicts

from .conftest import wait_for

NAMES = ["HeadYaw", "HeadPitch", "LHand"]


def _frame(seq: int, t: float | None = None, values: list[float] | None = None) -> bytes:
    return codec.encode(framing.frame(time.time() - 1 if t is None else t, seq, NAMES, values or [0.1, 0.2, 0.3]))


@pytest.fixture
def checks(monkeypatch):
    """The gate's checks of this test, counted (the real ``Gate.verdict``, what ``Gate.check`` calls, does each)."""
    counted = []
    check = messages.Gate.verdict

    def counting(gate, key, payload):
        counted.append(key.key)
        return check(gate, key, payload)

    monkeypatch.setattr(messages.Gate, "verdict", counting)
    return counted


def test_the_nodes_of_a_process_check_a_frame_once_and_each_gets_it(net, checks):
    robot, show = net.bus("robot"), net.bus("show")
    queues = {node: SampleQueue() for node in ("osc", "recorder", "foxglove")}
    streams = {node: Streams(show.for_node(node), ["pepper/joints/*"], queue, pace=False)
               for node, queue in queues.items()}
    publisher = robot.session.declare_publisher("pepper/frame", congestion_control=zenoh.CongestionControl.BLOCK,
                                                reliability=zenoh.Reliability.RELIABLE)
    wait_for(lambda: publisher.matching_status.matching, what="the subscriptions")
    try:
        for seq in range(5):
            publisher.put(_frame(seq, values=[0.1 * seq, 0.2, 0.3]))
        got = {node: [] for node in queues}
        for node, queue in queues.items():
            wait_for(lambda q=queue, n=node: got[n].extend(q.drain(0)) or len(got[n]) >= 5, what=f"{node}'s frames")
        for node, items in got.items():
            taken = [streams[node].take(key, payload, lambda *a: None, pytest.fail) for key, payload in items]
            assert [(m.seq, m.values) for m in taken] == [(seq, (0.1 * seq, 0.2, 0.3)) for seq in range(5)]
        assert checks == ["pepper/frame"] * 5  # once a frame for the three nodes (before: three times)
    finally:
        publisher.undeclare()
        for s in streams.values():
            s.undeclare()


def test_nodes_with_different_limits_each_get_their_own_verdict(checks):
    strict = Selection(["*/joints/*"], Limits(max_future_s=5))
    lenient = Selection(["*/joints/*"], Limits(max_future_s=600))
    for first, second in ((strict, lenient), (lenient, strict)):
        ahead = _frame(len(checks), t=time.time() + 60)  # a minute ahead: the strict node's clocks are out of step
        verdicts = {}
        for selection in (first, second):
            try:
                verdicts[selection] = selection.incoming("pepper/frame", ahead).t
            except BadMessage as exc:
                verdicts[selection] = str(exc)
        assert "is not a time between 1970 and 5 s from now" in verdicts[strict]
        assert verdicts[lenient] == pytest.approx(time.time() + 60, abs=5)
    # and two nodes with the same limits (one bus's) share the check
    same = Limits(max_future_s=5)
    payload, before, nodes = _frame(99), len(checks), [Selection(["*/joints/*"], same) for _ in range(2)]
    assert [node.incoming("pepper/frame", payload).seq for node in nodes] == [99, 99]
    assert len(checks) == before + 1


def test_a_process_of_one_node_remembers_nothing():
    """Remembering costs a sink alone (a copy of each message, the table): it checks as before."""
    verdicts, gate, key = Verdicts(), messages.Gate(), Key.parse("pepper/frame")
    verdicts.join()
    payload = _frame(5)
    assert verdicts.check(gate, key, payload)["seq"] == verdicts.check(gate, key, payload)["seq"] == 5
    assert len(verdicts) == 0 and verdicts.checked == 0
    verdicts.join()  # a second node: remembered
    verdicts.check(gate, key, payload)
    assert len(verdicts) == 1 and verdicts.checked == 1
    verdicts.leave()  # alone again: forgotten
    assert len(verdicts) == 0


def test_a_refused_frame_is_refused_for_each_node_with_its_reason(checks):
    bad = _frame(1, values=[0.1, 1e300, 0.3])
    reasons, nodes = [], [Selection(["*/joints/*"]) for _ in range(3)]
    for selection in nodes:
        counted: dict[str, int] = {}
        assert selection.take("pepper/frame", bad, lambda what, n, c=counted: c.update({what: c.get(what, 0) + n}),
                              lambda what, text: reasons.append(text)) is None
        assert counted == {"received": 1, "bad": 1}  # each node counts it
    assert reasons == ["message on 'pepper/frame' refused: v[1] = 1e+300 is outside ±1e+06"] * 3
    assert checks == ["pepper/frame"]


def test_a_node_that_changes_its_message_changes_no_other_nodes():
    frame = _frame(3, values=[0.5, 0.6, 0.7])
    derived = codec.encode(framing.derived_frame(time.time() - 1, 3, ["qom/all", "hand/R"], [0.2, [0.1, 0.0, 0.3]]))
    patterns = ["*/joints/*", "*/derived/**"]
    first = Selection(patterns)
    mine = first.incoming("pepper/frame", frame).message
    mine["v"][0], mine["t"] = 99.0, 0.0
    mine["names"].append("Extra")
    del mine["seq"]
    theirs = first.incoming("pepper/derived", derived)
    theirs.message["v"][1][0] = 99.0
    theirs.message["names"][0] = "qom/none"
    for selection in (Selection(patterns), first):  # another node, and the same one again
        assert selection.incoming("pepper/frame", frame).message == codec.decode(frame)
        again = selection.incoming("pepper/derived", derived)
        assert again.message == codec.decode(derived)
        assert [(part.source.key, part.values) for part in again.parts] == \
            [("pepper/derived/qom/all", (0.2,)), ("pepper/derived/hand/R", (0.1, 0.0, 0.3))]


def test_what_is_remembered_is_bounded():
    verdicts, gate, key = Verdicts(items=8, size=64 << 10), messages.Gate(), Key.parse("pepper/frame")
    verdicts.join()
    verdicts.join()
    for seq in range(100):
        assert verdicts.check(gate, key, _frame(seq))["seq"] == seq
        assert len(verdicts) <= 8
    huge = codec.encode(framing.frame(time.time() - 1, 0, [f"J{i}" for i in range(128)], [0.0] * 128,
                                       {f"q{i}": [0.0] * 128 for i in range(12)}))
    assert 12 << 10 < len(huge) < 64 << 10
    verdicts.check(gate, key, huge)  # (counted 4 bytes a byte: over the table's 64 KiB, not kept)
    assert len(verdicts) <= 8 and verdicts._table.held <= 64 << 10


def test_threads_checking_the_same_frames_each_get_their_own_right_message():
    payloads = [_frame(seq, values=[seq * 1e-3, 0.2, 0.3]) for seq in range(300)]
    wrong: list[str] = []

    def node(index: int) -> None:
        selection, order = Selection(["*/joints/*"]), list(range(len(payloads)))
        random.Random(index).shuffle(order)
        for seq in order:
            message = selection.incoming("pepper/frame", payloads[seq]).message
            if message["seq"] != seq or message["v"][0] != seq * 1e-3:
                wrong.append(f"node {index}: {message} for {seq}")
            message["v"][0] = -1.0  # (its own: no other thread may see this)

    threads = [threading.Thread(target=node, args=(i,)) for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(10)
    assert not wrong
