"""A subscription a broader one of its process includes (``pepper/frame`` in ``*/frame``) is
served by the broader one's Zenoh subscriber, given only its own keys (``bus/fanout.py``,
issue 35); a subscription never moves between Zenoh subscribers, so none gets a sample twice,
loses one or gets them out of order when a broader one comes after it or leaves before it."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import msgpack
import zenoh

from sonibus.bus import Adapter, codec, runner
from sonibus.bus.fanout import MAX_ROUTES, Fanout
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Streams

from .conftest import wait_for
from .test_fanout import _drained, _publisher, _threads


def _seqs(items: list) -> list[int]:
    return [msgpack.unpackb(item[1])["seq"] for item in items]


class Stream:
    """Samples with their ``seq`` put on ``key`` from a thread until ``stop`` (reliable, blocking: every one
    counts), so that subscriptions join and leave while samples are on their way."""

    def __init__(self, net, key: str) -> None:
        self.publisher, self.sent, self.done = _publisher(net, key), 0, threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.done.is_set() and self.sent < 3000:
            self.publisher.put(msgpack.packb({"seq": self.sent}))
            self.sent += 1
            if self.sent % 20 == 0:
                self.done.wait(0.002)  # (a robot's pace, roughly: not a flood the queues would drop)

    def stop(self) -> int:
        self.done.set()
        self.thread.join(10)
        assert not self.thread.is_alive()
        return self.sent


def test_a_robots_subscription_is_served_by_the_subscriber_of_every_robots_and_gets_only_its_keys(net):
    show = net.bus("show")
    _, every = show.for_node("recorder").subscribe("*/frame", maxlen=4096)
    before = _threads()
    _, pepper = show.for_node("osc").subscribe("pepper/frame", maxlen=4096)
    assert _threads() == before  # no Zenoh subscriber (and thread) of its own: one more before
    publishers = {robot: _publisher(net, f"{robot}/frame") for robot in ("pepper", "nao")}
    for n in range(100):
        publishers["pepper" if n % 3 else "nao"].put(msgpack.packb({"seq": n}))
    got = _drained(every, 100)
    assert {key for key, _ in got} == {"pepper/frame", "nao/frame"}
    for robot in ("pepper", "nao"):  # (each publisher's samples in the order put)
        assert _seqs([item for item in got if item[0] == f"{robot}/frame"]) == \
            [n for n in range(100) if (n % 3 != 0) == (robot == "pepper")]
    assert _seqs(_drained(pepper, 66)) == [n for n in range(100) if n % 3]
    assert pepper.drain(0.2) == []  # nothing of nao's


def test_planned_the_narrower_first_is_served_by_the_broader_ones_subscriber(net):
    show = net.bus("show")
    show.plan(["*/frame", "*/events/*"])
    _, pepper = show.for_node("osc").subscribe("pepper/frame", maxlen=4096)
    publisher = _publisher(net, "nao/frame")  # the Zenoh subscriber is the broader one's already
    before = _threads()
    _, every = show.for_node("recorder").subscribe("*/frame", maxlen=4096)
    assert _threads() == before  # (before: a subscriber of its own)
    for n in range(20):
        publisher.put(msgpack.packb({"seq": n}))
    assert _seqs(_drained(every, 20)) == list(range(20))
    assert pepper.drain(0.2) == []


def test_a_process_of_one_robot_subscribes_to_that_robot_alone(net):
    show = net.bus("show")
    show.plan(["pepper/frame", "pepper/events/*"])  # (every key expression of one robot: nothing broader)
    subscription, pepper = show.for_node("osc").subscribe("pepper/frame")
    assert subscription.via == "pepper/frame"
    robot = net.bus("robot").session
    ours, nao = robot.declare_publisher("pepper/frame"), robot.declare_publisher("nao/frame")
    wait_for(lambda: ours.matching_status.matching, what="the subscription")
    ours.put(b"1")
    assert _drained(pepper, 1) == [("pepper/frame", b"1")]
    assert not nao.matching_status.matching  # another robot's frames do not come to this process


def test_a_broader_subscription_after_the_narrower_leaves_it_every_sample_once_in_order(net):
    show = net.bus("show")
    _, pepper = show.for_node("osc").subscribe("pepper/frame", maxlen=4096)
    stream = Stream(net, "pepper/frame")
    got: list = []
    wait_for(lambda: got.extend(pepper.drain(0)) or len(got) >= 50, what="samples before the broader one")
    subscription, every = show.for_node("recorder").subscribe("*/frame", maxlen=4096)
    assert subscription.via == "*/frame"  # (a subscriber of its own: the narrower one is not moved)
    wait_for(lambda: len(every) >= 100, what="samples of the broader one")
    sent = stream.stop()
    assert _seqs(got + _drained(pepper, sent - len(got))) == list(range(sent))
    tail = _seqs(_drained(every, 1)) + _seqs(every.drain(0.2))
    assert tail == list(range(tail[0], sent))  # from its first sample on, every one, once, in order


def test_the_broader_leaving_mid_stream_leaves_the_narrower_every_sample_once_in_order(net):
    show = net.bus("show")
    broader, every = show.for_node("recorder").subscribe("*/frame", maxlen=4096)
    narrower, pepper = show.for_node("osc").subscribe("pepper/frame", maxlen=4096)
    assert narrower.via == "*/frame"
    stream = Stream(net, "pepper/frame")
    got: list = []
    wait_for(lambda: got.extend(pepper.drain(0)) or len(got) >= 50, what="samples before the broader one leaves")
    broader.undeclare()
    before = len(got)
    wait_for(lambda: got.extend(pepper.drain(0)) or len(got) >= before + 100, what="samples after it left")
    sent = stream.stop()
    assert _seqs(got + _drained(pepper, sent - len(got))) == list(range(sent))
    assert pepper.drain(0.2) == []
    head = _seqs(every.drain(0))
    assert head == list(range(len(head))) and len(head) >= 50  # the broader one's, until it left
    assert stream.publisher.matching_status.matching  # (the Zenoh subscriber serves the narrower one still)
    narrower.undeclare()
    wait_for(lambda: not stream.publisher.matching_status.matching, what="the Zenoh subscriber to be undeclared")


def test_each_subscription_on_the_broader_subscriber_keeps_its_own_limit_and_skip(net):
    show = net.bus("show")
    _, every = show.for_node("recorder").subscribe("*/events/*")
    before = _threads()
    _, small = show.for_node("ros").subscribe("pepper/events/*", max_payload=100, attachment=True,
                                              skip=lambda key: key.endswith("/skipped"))
    assert _threads() == before
    robot = net.bus("robot").session
    publisher = robot.declare_publisher("pepper/events/a")
    wait_for(lambda: publisher.matching_status.matching, what="the subscriptions")
    for key, payload in (("pepper/events/a", b"s" * 50), ("pepper/events/skipped", b"x"),
                         ("nao/events/a", b"n"), ("pepper/events/b", b"b" * 500)):
        robot.put(key, payload, attachment=b"at", congestion_control=zenoh.CongestionControl.BLOCK)
    assert _drained(small, 2) == [("pepper/events/a", b"s" * 50, b"at"),
                                  ("pepper/events/b", codec.Oversize(500), b"at")]
    assert [key for key, _ in _drained(every, 4)] == ["pepper/events/a", "pepper/events/skipped",
                                                      "nao/events/a", "pepper/events/b"]
    assert small.drain(0.2) == []


def test_one_streams_subscribes_the_broadest_first_so_one_serves_both(net):
    show = net.bus("show")
    streams = Streams(show, ["pepper/derived/qom/*", "*/derived/**"], SampleQueue(64))
    try:
        assert show._subscriptions.declared == 2  # */derived and */derived/*/** (before: 3, one more for qom)
    finally:
        streams.undeclare()


def test_the_keys_a_broader_subscriber_remembers_are_capped():
    """Keys come from the network: the table of which subscriptions each key goes to stops growing
    (past it, a key's subscriptions are worked out each time), and each still gets its own keys."""
    callbacks: list = []
    fanout = Fanout(lambda keyexpr, callback: callbacks.append(callback) or SimpleNamespace(undeclare=lambda: None))
    every: list[str] = []
    pepper: list[str] = []
    fanout.join("*/frame", lambda key, payload, sample: every.append(key), lambda key, size: True)
    narrower = fanout.join("pepper/frame", lambda key, payload, sample: pepper.append(key), lambda key, size: True)
    [dispatch] = callbacks
    for n in range(3 * MAX_ROUTES):
        dispatch(SimpleNamespace(key_expr=f"robot{n}/frame", payload=zenoh.ZBytes(b"")))
        dispatch(SimpleNamespace(key_expr="pepper/frame", payload=zenoh.ZBytes(b"")))
    assert len(every) == 6 * MAX_ROUTES and pepper == ["pepper/frame"] * 3 * MAX_ROUTES
    assert len(fanout._shared["*/frame"].members.routes) == MAX_ROUTES
    narrower.undeclare()


class Taker(Adapter):
    """A node of ``subscribe``'s patterns through ``Streams``, as a sink (its samples in ``queue``)."""

    @dataclass(frozen=True)
    class Config:
        subscribe: tuple[str, ...] = ()

    def _start(self) -> None:
        self.queue = SampleQueue(1024)
        self.own(Streams(self.bus, self.config.subscribe, self.queue, pace=False))


def test_sonibus_run_plans_so_a_robots_node_before_one_of_every_robot_shares_its_subscriber(net):
    robot = net.bus("robot")
    nodes = [Taker(Taker.Config(("pepper/joints/*",)), name="osc"), Taker(Taker.Config(("*/joints/*",)), name="rec")]
    stop, buses = threading.Event(), []
    thread = threading.Thread(target=runner.run, args=(nodes, net.config(), stop),
                              kwargs={"on_started": buses.append}, daemon=True)
    thread.start()
    try:
        wait_for(lambda: buses, 10, "the nodes to start")
        fanout: Any = buses[0]._subscriptions
        # the robot's node first, yet one Zenoh subscriber for both (before: one for each)
        assert (fanout.subscriptions("*/frame"), fanout.subscriptions("pepper/frame")) == (2, 0)
        publisher = robot.session.declare_publisher("pepper/frame")
        wait_for(lambda: publisher.matching_status.matching, 10, "the run's subscriber")
        publisher.put(codec.encode({"t": 1.0, "seq": 1, "names": ["HeadYaw"], "v": [0.5]}))
        for node in nodes:
            assert [key for key, _ in _drained(node.queue, 1)] == ["pepper/frame"]
    finally:
        stop.set()
        thread.join(10)
    assert not thread.is_alive()
