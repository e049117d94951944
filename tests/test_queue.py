"""A sample queue is bounded in bytes as well as in items: a flood of payloads as big as
the gate lets through (64 KiB) at a node that does not keep up holds at most its byte
budget, keeps the newest, and counts what it dropped."""

from __future__ import annotations

import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from sonibus.bus.queue import ITEM_BYTES, SampleQueue, item_size

from .conftest import wait_for

BIG = 60_000  # bytes of each payload: under the gate's 64 KiB


def test_a_flood_of_big_payloads_at_a_stalled_consumer_holds_its_byte_budget_and_keeps_the_newest(net):
    budget = 4 << 20
    listener, rogue = net.bus("sink"), net.bus("rogue")
    queue = SampleQueue(8192, max_bytes=budget)  # (8,192 items of 60 KB would be 480 MB)
    subscriber, _ = listener.subscribe("pepper/events/*", queue=queue)
    # (blocking: every payload reaches the subscription, none is dropped on the way by Zenoh)
    publisher = rogue.session.declare_publisher("pepper/events/flood", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_for(lambda: publisher.matching_status.matching, what="the subscription")
    for n in range(1000):
        publisher.put(n.to_bytes(4, "big") + bytes(BIG))
    wait_for(lambda: len(queue) + queue.dropped == 1000, what="every payload queued or counted dropped")
    assert queue.bytes <= budget and queue.bytes == sum(item_size(item) for item in list(queue._items))
    assert len(queue) == budget // (BIG + 4 + ITEM_BYTES)
    kept = [int.from_bytes(item[1][:4], "big") for item in queue.drain()]
    assert kept == list(range(1000 - len(kept), 1000))  # the newest, in order
    assert queue.bytes == 0
    subscriber.undeclare()


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(st.tuples(st.just("put"), st.integers(0, 5000)), st.just(("get", 0)),
                          st.just(("drain", 0))), max_size=200),
       st.integers(1, 50), st.integers(1, 20_000))
def test_what_a_queue_counts_is_what_it_holds(steps, maxlen, budget):
    queue = SampleQueue(maxlen, max_bytes=budget)
    put = dropped = taken = 0
    for op, size in steps:
        if op == "put":
            queue.put(("k", bytes(size)))
            put += 1
        elif op == "get":
            taken += queue.get(timeout=0) is not None
        else:
            taken += len(queue.drain(timeout=0))
        held = list(queue._items)
        assert queue.bytes == sum(item_size(item) for item in held)
        assert len(held) <= maxlen and (queue.bytes <= budget or len(held) == 1)  # (one too big is kept alone)
        dropped = queue.dropped
    assert put == taken + len(queue) + dropped


def test_a_wake_returns_a_waiting_consumer_at_once_and_a_flood_of_them_pushes_no_item_out():
    import threading
    import time

    queue = SampleQueue(maxlen=4)
    for i in range(4):
        queue.put(("pepper/frame", bytes([i])))
    for _ in range(10_000):  # (a stranger's tokens, each waking the worker)
        queue.wake()
    assert queue.dropped == 0 and [p for _, p in queue.drain()] == [bytes([i]) for i in range(4)]
    got: list = []
    waiter = threading.Thread(target=lambda: got.append(queue.drain(timeout=30)))
    waiter.start()
    time.sleep(0.05)  # (the waiter most likely waits by now; if not, the wake still holds for it)
    started = time.monotonic()
    queue.wake()
    waiter.join(5)
    assert not waiter.is_alive() and got == [[]] and time.monotonic() - started < 5
    queue.put(("pepper/frame", b"x"))
    assert queue.drain(timeout=0) == [("pepper/frame", b"x")]
