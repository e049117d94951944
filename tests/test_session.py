"""Closing a session while another thread is using it."""

from __future__ import annotations

import threading
import time

import zenoh

from sonibus.bus import Bus, BusConfig, codec
from sonibus.bus import session as session_module
from sonibus.bus.cli.api import joined

from .conftest import free_port, wait_for

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


def test_discovery_for_a_served_key_waits_until_its_queryable_is_known(monkeypatch):
    """``sonibus send``/``resume`` wait, once linked, until a queryable of the key they ask is
    known (at most the settle time). The wait read the matching status object, which is always
    true, and ended at once: a new session's query could go before the queryable was known, and
    ``sonibus resume`` said "served by nothing" of a running map node (a CI run)."""
    monkeypatch.setattr(session_module, "LINK_SETTLE_S", 10.0)  # (long: the queryable comes first)
    port = free_port()
    declared = threading.Event()
    with joined(BusConfig(multicast=False, listen=(f"tcp/127.0.0.1:{port}",))) as server, \
            joined(BusConfig(multicast=False, connect=(f"tcp/127.0.0.1:{port}",))) as asker:
        def serve_later() -> None:
            wait_for(lambda: asker.session.info.peers_zid(), what="the link")
            time.sleep(0.3)  # (a queryable declared after the link: what discovery must wait for)
            declared.set()
            server.serve("moves/program/resume", lambda query: query.reply(query.key_expr, codec.encode({})))
        thread = threading.Thread(target=serve_later)
        thread.start()
        try:
            asker.discover("moves/program/resume")
            assert declared.is_set(), "discovery ended before the queryable was declared"
            assert asker.query("moves/program/resume", {}, timeout=2.0)
        finally:
            thread.join(5)
