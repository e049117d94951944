"""A running show as its supervisor sees it: started, healthy, stopping.

``sonibus run`` tells systemd (``bus/notify.py``) ``READY=1`` once every node has
started, and then ``WATCHDOG=1`` every third of the watchdog's timeout — but only
while every node is healthy (``Adapter.health``: running, not failed, not hung).
A node that hangs therefore stops the pings, and systemd kills and restarts the
process when the timeout runs out; a process that hangs as a whole (a native call
holding the interpreter) stops them too. ``STATUS=`` says what it is doing or what
is wrong, for ``systemctl status``. Without a supervisor the same checks run once
a second, and a node that turns unhealthy, or healthy again, is logged.

>>> from .notify import Notifier
>>> watchdog = Watchdog(Notifier({}), [])
>>> watchdog.check()   # no nodes, no supervisor: healthy, nobody to tell
True
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Iterator, Sequence

from .adapter import Adapter
from .notify import Notifier

log = logging.getLogger(__name__)

CHECK_EVERY_S = 1.0  # health checks without a watchdog (for the log)
EXTEND_S = 10.0      # while joining the bus: the start may take this much longer, said again every 2 s


class Watchdog:
    """What the supervisor behind ``notifier`` hears of ``adapters``; ``check`` is called
    often (every 0.1 s) from the thread that runs them, and acts at its own pace."""

    def __init__(self, notifier: Notifier, adapters: Sequence[Adapter]) -> None:
        self.notifier = notifier
        self.adapters = adapters
        self.every_s = notifier.watchdog_s / 3 if notifier.watchdog_s else CHECK_EVERY_S
        self.problems: list[str] = []
        self._status = ""
        self._next = 0.0

    @contextlib.contextmanager
    def joining(self, what: str) -> Iterator[None]:
        """While inside (a client waiting for its router can wait long), tell the
        supervisor every 2 s that the start goes on, so its start timeout bounds the
        nodes' starts, not the wait for the bus."""
        self.status(what)
        if not self.notifier.enabled:
            yield
            return
        done = threading.Event()

        def extend() -> None:
            while True:
                self.notifier.send(EXTEND_TIMEOUT_USEC=int(EXTEND_S * 1e6))
                if done.wait(2.0):
                    return

        thread = threading.Thread(target=extend, name="supervisor:joining", daemon=True)
        thread.start()
        try:
            yield
        finally:
            done.set()
            thread.join()

    def status(self, text: str) -> None:
        """What the process is doing, for ``systemctl status``."""
        self.notifier.send(STATUS=text)

    def ready(self, status: str) -> None:
        """Every node started: ``READY=1`` and the status it keeps while healthy."""
        self._status = status
        self.notifier.send(READY=1, STATUS=status)
        self._next = 0.0
        self.check()

    def check(self) -> bool:
        """If due: ask every node how it is, and ping the watchdog only if all are well
        (else say what is wrong, again at each check). Whether all were well."""
        now = time.monotonic()
        if now < self._next:
            return not self.problems
        self._next = now + self.every_s
        problems = [f"node '{a.name}' {problem}" for a in self.adapters if (problem := a.health())]
        if problems != self.problems:
            if problems:
                log.warning("unhealthy: %s%s", "; ".join(problems),
                            " — the watchdog is no longer fed: systemd restarts this process within "
                            f"{self.notifier.watchdog_s:g} s" if self.notifier.watchdog_s else "")
            elif self.problems:
                log.warning("healthy again: every node runs")
        recovered = self.problems and not problems
        self.problems = problems
        if problems:
            self.notifier.send(STATUS="unhealthy: " + "; ".join(problems))
        elif self.notifier.watchdog_s:
            self.notifier.send(WATCHDOG=1, **({"STATUS": self._status} if recovered else {}))
        elif recovered:
            self.notifier.send(STATUS=self._status)
        return not problems

    def stopping(self, why: str) -> None:
        """The nodes are being stopped (``why``): no more pings are coming."""
        self.notifier.send(STOPPING=1, STATUS=f"stopping: {why}")
