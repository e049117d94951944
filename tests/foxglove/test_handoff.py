"""What the Foxglove node hands its server's loop (``framed.Handoff``, issue 35) is bounded:
while the loop does not come round (held, or slow), samples past ``most`` or ``most_bytes``
are refused (the node's own queue takes them, bounded and counted there), the loop is asked
once for all that waits, and what it serves comes in order; a server that is not running
keeps nothing."""

from __future__ import annotations

from typing import Any

from sonibus.adapters.foxglove.framed import Handoff


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
