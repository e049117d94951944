"""The sim's loops wait between ticks with ``time.sleep`` (``Nap``), not ``Event.wait``.

A wake-up from ``time.sleep`` costs a thread ~60-70 µs on this 2-core VM against
~100-110 µs from ``Event.wait`` with a timeout (a lock made and waited on with a
deadline; docs/performance.md, "The sim and the recorder against their floors"), and
the frame loop wakes ``rate_hz`` times a second, the microphone's and speaker's 50
while they play.
"""

from __future__ import annotations

import threading
import time

NAP_S = 0.05  # a loop sleeps at most this long between looks at its stop (Ctrl-C, stop())


class Nap:
    """A stop event as ``Pacer.run`` waits on it, waited on with ``time.sleep`` in slices of
    ``NAP_S`` at most (a stop is seen within that; a wait is never cut short otherwise,
    or the pacer would tick early).

    >>> import threading
    >>> stop = threading.Event()
    >>> Nap(stop).wait(0.01), stop.set(), Nap(stop).wait(10.0)
    (False, None, True)
    """

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop
        self.is_set = stop.is_set  # (the pacer asks it every tick: the event's own, no call in between)

    def wait(self, timeout: float) -> bool:
        """Sleep ``timeout`` seconds, or until the stop is seen; whether it is set."""
        is_set = self.stop.is_set
        if timeout <= NAP_S:  # (a frame loop's wait: one sleep)
            if timeout > 0 and not is_set():
                time.sleep(timeout)
            return is_set()
        end = time.monotonic() + timeout
        while not is_set():
            left = end - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(left, NAP_S))
        return is_set()
