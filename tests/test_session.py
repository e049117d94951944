"""Closing a session while another thread is using it."""

from __future__ import annotations

import threading

import zenoh

from sonibus.bus import Bus, BusConfig
from sonibus.bus.cli.api import joined

TRIES = 30


def put_until_closed(bus: Bus, busy: threading.Event) -> None:
    while True:
        try:
            bus.put("pepper/events/hello", {"t": 0.0, "kind": "hello"})
        except zenoh.ZError:  # the session closed: what a callback meets on the way out
            return
        busy.set()


def test_a_session_closes_while_another_thread_is_using_it():
    """zenoh's own ``with session`` failed on exit ("RuntimeError: Already borrowed") when
    another thread was inside a session call at that instant (an owner's conflict event
    as its node stopped: a test saw it, and ``sonibus run`` would have exited 1)."""
    for _ in range(TRIES):
        busy = threading.Event()
        with joined(BusConfig(multicast=False)) as bus:  # (the runner closes its session the same way)
            putting = threading.Thread(target=put_until_closed, args=(bus, busy))
            putting.start()
            assert busy.wait(5.0), "no put went out"
        putting.join(5.0)
        assert not putting.is_alive(), "a put on a closed session did not end"
