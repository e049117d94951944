"""What the Foxglove node hands its server's loop (``framed.Handoff``, issue 35) is bounded:
while the loop does not come round (held, or slow), samples past ``most`` or ``most_bytes``
are refused (the node's own queue takes them, bounded and counted there), the loop is asked
once for all that waits, and what it serves comes in order; a server that is not running
keeps nothing; with ``gather_s`` the loop comes round by itself while samples come."""

from __future__ import annotations

import asyncio
import threading
from typing import Any

import pytest

from sonibus.adapters.foxglove.framed import Handoff

from ..conftest import wait_for


class HeldLoop:
    """A web server whose loop does not come round until ``run``: ``call`` takes the callback
    (True, as ``WebServer.call`` does while running) or, ``running=False``, refuses it."""

    def __init__(self, running: bool = True) -> None:
        self.running, self.calls = running, []

    def call(self, function: Any, *args: Any) -> bool:
        if self.running:
            self.calls.append((function, args))
        return self.running

    def run(self) -> None:
        calls, self.calls = self.calls, []
        for function, args in calls:
            function(*args)


def test_a_held_loop_is_asked_once_and_what_waits_is_bounded_by_count_and_bytes():
    served: list[list[tuple[str, Any]]] = []
    loop = HeldLoop()
    handoff = Handoff(loop, served.append, most=64, most_bytes=4 << 20)  # type: ignore[arg-type]
    assert all(handoff.put("pepper/frame", bytes([i])) for i in range(64))
    assert not handoff.put("pepper/frame", b"x")  # (the 65th: to the node's queue)
    assert len(loop.calls) == 1  # the loop asked once for all of them
    loop.run()
    assert [payload for _, payload in served[0]] == [bytes([i]) for i in range(64)]
    assert handoff.put("pepper/frame", b"a" * (3 << 20))  # (one alone always goes, whatever its size)
    assert not handoff.put("pepper/frame", b"b" * (2 << 20))  # 5 MiB would wait
    assert handoff.put("pepper/frame", b"c" * 1000)
    loop.run()
    assert [len(payload) for _, payload in served[1]] == [3 << 20, 1000]
    assert handoff.put("pepper/frame", b"b" * (2 << 20))  # (served: room again)


def test_a_server_not_running_keeps_nothing():
    served: list[list[tuple[str, Any]]] = []
    loop = HeldLoop(running=False)
    handoff = Handoff(loop, served.append)  # type: ignore[arg-type]
    assert not handoff.put("pepper/frame", b"x")
    loop.running = True
    assert handoff.put("pepper/frame", b"y")
    loop.run()
    assert served == [[("pepper/frame", b"y")]]


class Loop:
    """A running asyncio loop in a thread, as ``WebServer``'s: ``call`` counts what asks it."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.asked = 0

    def call(self, function: Any, *args: Any) -> bool:
        self.asked += 1
        self.loop.call_soon_threadsafe(function, *args)
        return True

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.loop.close()


@pytest.fixture
def loop():
    running = Loop()
    try:
        yield running
    finally:
        running.close()


def test_with_gather_s_the_loop_comes_round_by_itself_while_samples_come_and_stops_when_none_do(loop):
    """``gather_s``: after serving, the loop comes round again by itself and serves what came
    meanwhile in one batch, nobody asking it (no wake-up from the callback threads); a round
    that finds nothing ends that, and the next sample asks the loop again."""
    served: list[list[bytes]] = []
    handoff = Handoff(loop, lambda items: served.append([p for _, p in items]), gather_s=0.4)  # type: ignore[arg-type]
    assert handoff.put("pepper/frame", b"1")
    wait_for(lambda: served == [[b"1"]], 5, "the first sample served at once")
    assert handoff.put("pepper/frame", b"2") and handoff.put("pepper/derived", b"3")  # (within gather_s)
    assert loop.asked == 1  # the loop comes round by itself: not asked for them
    wait_for(lambda: len(served) == 2, 5, "what came served by the next round")
    assert served[1] == [b"2", b"3"]
    wait_for(lambda: not handoff._armed, 5, "a round that found nothing")
    assert handoff.put("pepper/frame", b"4")
    assert loop.asked == 2  # asked again, served at once
    wait_for(lambda: len(served) == 3, 5, "the next sample served")
    assert served[2] == [b"4"]
