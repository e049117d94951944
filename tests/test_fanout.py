"""Subscriptions of one process to one key expression share one Zenoh subscriber
(``bus/fanout.py``, issue 35): each still gets every sample, in order, as its own
options say; one undeclared or failing leaves the others served."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path

import msgpack
import zenoh

from sonibus.bus import Adapter, codec
from sonibus.bus.fanout import Fanout

from .conftest import wait_for
from .test_node_failure import Fussy  # (its skip raises on a key ending in "surprise")

KEY = "pepper/events/fanout"


def _threads() -> int:
    """Python's native threads in this process: zenoh-python starts one per subscriber with a
    Python callback (named as the process is; Zenoh's own runtime threads have names of their
    own, and may come and go)."""
    python = Path("/proc/self/comm").read_text()
    count = 0
    for task in Path("/proc/self/task").iterdir():
        try:
            count += (task / "comm").read_text() == python
        except FileNotFoundError:  # (a thread that just ended)
            continue
    return count


def _publisher(net, key: str = KEY):
    # (reliable and blocking: Zenoh's default drops under congestion, and these tests count every sample)
    publisher = net.bus("robot").session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK,
                                                           reliability=zenoh.Reliability.RELIABLE)
    wait_for(lambda: publisher.matching_status.matching, what="the subscriptions")
    return publisher


def _drained(queue, count: int) -> list:
    got = []
    wait_for(lambda: got.extend(queue.drain(0)) or len(got) >= count, what=f"{count} samples",
             explain=lambda: f"got {len(got)}")
    return got


def test_the_nodes_of_a_process_share_one_zenoh_subscriber_per_key_expression(net):
    show = net.bus("show")
    show.for_node("a").subscribe(KEY)  # (the first: Zenoh's runtime may start threads of its own)
    before = _threads()
    for node in ("b", "c", "d"):
        show.for_node(node).subscribe(KEY)
    show.for_node("e").on_sample(f" {KEY} ", lambda key, payload: None, "e")  # (the same, as keys.expr writes it)
    shared = _threads()
    show.for_node("f").subscribe("pepper/events/other")  # another key expression: a subscriber of its own
    assert (shared - before, _threads() - before) == (0, 1)


def test_two_nodes_on_one_key_each_get_every_sample_in_order(net):
    show = net.bus("show")
    _, queue = show.for_node("recorder").subscribe(KEY)
    taken: list[tuple[str, bytes]] = []
    show.for_node("map").on_sample(KEY, lambda key, payload: taken.append((key, payload)), "map's events")
    publisher = _publisher(net)
    sent = [msgpack.packb({"t": 1.0, "kind": "x", "seq": n}) for n in range(300)]
    for payload in sent:
        publisher.put(payload)
    assert _drained(queue, 300) == [(KEY, p) for p in sent]
    wait_for(lambda: len(taken) >= 300, what="the second node's samples")
    assert taken == [(KEY, p) for p in sent]


def test_one_undeclared_the_other_still_gets_them_and_the_last_undeclares_the_subscriber(net):
    show = net.bus("show")
    first, first_queue = show.for_node("a").subscribe(KEY)
    second, second_queue = show.for_node("b").subscribe(KEY)
    publisher = _publisher(net)
    publisher.put(b"1")
    assert _drained(first_queue, 1) == _drained(second_queue, 1) == [(KEY, b"1")]
    first.undeclare()
    first.undeclare()  # (twice: nothing more)
    for n in range(2, 12):
        publisher.put(str(n).encode())
    assert _drained(second_queue, 10) == [(KEY, str(n).encode()) for n in range(2, 12)]
    assert first_queue.drain(0) == []
    assert publisher.matching_status.matching
    second.undeclare()
    wait_for(lambda: not publisher.matching_status.matching, what="the Zenoh subscriber to be undeclared")


class Listener(Adapter):
    @dataclass(frozen=True)
    class Config:
        pass

    def _start(self) -> None:
        subscriber, self.queue = self.bus.subscribe("pepper/events/*")
        self.own(subscriber)


def test_a_node_whose_handler_raises_fails_and_the_other_on_its_subscriber_is_still_served(net):
    show = net.bus("show")
    fussy = net.start(Fussy(name="fussy"), show)
    listener = net.start(Listener(name="listener"), show)
    _, plain_queue = show.subscribe("pepper/events/*", skip=lambda key: 1 / 0)  # no node: Zenoh hears of it
    publisher = _publisher(net, "pepper/events/surprise")
    for n in range(5):
        publisher.put(msgpack.packb({"t": 1.0, "kind": "x", "seq": n}))
    wait_for(lambda: fussy.state == "failed", what="the node to fail")
    assert fussy.failure == "subscriber to pepper/events/* failed: KeyError: 'pepper/events/surprise'"
    assert [msgpack.unpackb(p)["seq"] for _, p in _drained(listener.queue, 5)] == list(range(5))
    assert listener.state == "running" and plain_queue.drain(0) == []


def test_a_small_max_payload_and_the_default_each_get_what_their_limit_says(net):
    show = net.bus("show")
    _, small = show.for_node("ros").subscribe(KEY, max_payload=100, attachment=True)
    _, default = show.for_node("osc").subscribe(KEY, stamped=True)
    publisher = _publisher(net)
    publisher.put(b"s" * 50, attachment=b"a")
    publisher.put(b"b" * 500)
    publisher.put(b"h" * 100_000)  # over the gate's 64 KiB too
    assert _drained(small, 3) == [(KEY, b"s" * 50, b"a"), (KEY, codec.Oversize(500), None),
                                  (KEY, codec.Oversize(100_000), None)]
    stamped = _drained(default, 3)
    assert [item[:2] for item in stamped] == [(KEY, b"s" * 50), (KEY, b"b" * 500), (KEY, codec.Oversize(100_000))]
    assert all(isinstance(item[2], int) for item in stamped)


def test_history_subscriptions_keep_a_subscriber_of_their_own(net):
    show = net.bus("show")
    show.for_node("a").subscribe(KEY)
    before = _threads()
    subscriber, _ = show.for_node("b").subscribe(KEY, history=True)
    try:
        assert _threads() - before == 1
    finally:
        subscriber.undeclare()


def test_nodes_declaring_and_undeclaring_at_once_leave_the_others_served(net):
    show = net.bus("show")
    subscription, steady = show.for_node("steady").subscribe(KEY)
    failures: list[BaseException] = []

    def churn(node: str) -> None:
        try:
            bus = show.for_node(node)
            for _ in range(40):
                bus.subscribe(KEY)[0].undeclare()
        except BaseException as exc:  # (said by the assertion below)
            failures.append(exc)

    workers = [threading.Thread(target=churn, args=(f"churn{n}",)) for n in range(6)]
    for worker in workers:
        worker.start()
    publisher = _publisher(net)
    for n in range(50):
        publisher.put(str(n).encode())
    for worker in workers:
        worker.join(30)
    assert not failures and not any(w.is_alive() for w in workers)
    assert _drained(steady, 50) == [(KEY, str(n).encode()) for n in range(50)]
    subscription.undeclare()  # the last one left: nothing of the churn holds the Zenoh subscriber
    wait_for(lambda: not publisher.matching_status.matching, what="the Zenoh subscriber to be undeclared")


def test_a_view_made_by_bus_shared_may_subscribe(net):
    """``Bus.shared`` makes a view under the Bus's lock; subscribing there must not wait on it."""
    show = net.bus("show")
    made: list = []
    maker = threading.Thread(target=lambda: made.append(show.shared("view", lambda bus: bus.subscribe(KEY))),
                             daemon=True)
    maker.start()
    maker.join(5)
    assert made, "Bus.shared's make could not subscribe (waiting on the Bus's own lock)"


def test_a_sample_that_comes_as_the_first_subscription_is_declared_is_its():
    """Zenoh may call a subscriber back as soon as it is declared (from its own thread, before
    ``declare_subscriber`` returns here): the first subscription was added only after, and such
    a sample went to nobody. A declare that calls back at once, as that race does."""
    class Payload(bytes):
        def to_bytes(self) -> bytes:
            return bytes(self)

    @dataclass
    class Sample:
        key_expr: str
        payload: Payload

    class Subscriber:
        def undeclare(self) -> None:
            pass

    def declare(keyexpr: str, callback) -> Subscriber:
        callback(Sample(keyexpr, Payload(b"early")))
        return Subscriber()

    got: list[tuple[str, bytes]] = []
    fanout = Fanout(declare)
    first = fanout.join("pepper/frame", lambda key, payload, sample: got.append((key, payload)),
                        lambda key, size: True)
    assert got == [("pepper/frame", b"early")]
    first.undeclare()
