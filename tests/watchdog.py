"""A hard bound on every test, behind pytest-timeout's.

pytest-timeout's signal method raises in the test when its alarm comes, but only once the
main thread is back in Python: a test stuck inside a native call (a Zenoh session's close,
a libqi future, a JACK client) never sees the alarm, and CI once waited 75 minutes on such
a test, printing nothing. This watchdog is a thread: a minute after the test's own timeout
it writes which test hung and where every thread of this process stands, kills the
processes this one started, and ends the process (in xdist, the worker: the run then
fails, naming the test, instead of hanging). A worker whose interpreter does not end after
the run ends the same way.
"""

from __future__ import annotations

import contextlib
import faulthandler
import os
import signal
import sys
import threading
from collections.abc import Iterator

import pytest

GRACE_S = 60.0  # past the test's own timeout, for pytest-timeout to act first
# past the watchdog's own time, for faulthandler's: a native call that holds the GIL (python-rtmidi's
# ``delete`` waiting on a JACK server) keeps every Python thread out, this one too, so the last
# bound is faulthandler's C thread, which needs no GIL: it prints every thread and ends the process
# (the processes it started are left then: they are killed only by ``_end``, which could not run)
BACKSTOP_S = 30.0
EXIT_GRACE_S = 60.0  # from the end of the run to the end of the process
HUNG = 70  # the exit status of a process ended by the watchdog


def _children() -> list[int]:
    me = str(os.getpid())
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[1] == me:
                found.append(int(entry))
    return found


def _end(why: str) -> None:
    out = sys.__stderr__
    if out is not None:
        out.write(f"\n\nWATCHDOG: {why}; the threads of process {os.getpid()}:\n")
        out.flush()
        faulthandler.dump_traceback(file=out, all_threads=True)
        out.flush()
    for child in _children():
        with contextlib.suppress(OSError):  # a child with a session of its own leads a group: end it all
            os.killpg(child, signal.SIGKILL) if os.getpgid(child) == child else os.kill(child, signal.SIGKILL)
    os._exit(HUNG)


def _timeout_s(item: pytest.Item) -> float:
    marker = item.get_closest_marker("timeout")
    if marker is not None and marker.args:
        return float(marker.args[0])
    return float(item.config.getini("timeout") or 120)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    timer = threading.Timer(_timeout_s(item) + GRACE_S, _end,
                            (f"{item.nodeid} did not end {GRACE_S:.0f} s after its timeout",))
    timer.daemon = True
    timer.start()
    _backstop(_timeout_s(item) + GRACE_S + BACKSTOP_S)
    try:
        yield
    finally:
        timer.cancel()
        faulthandler.cancel_dump_traceback_later()


def pytest_unconfigure(config: pytest.Config) -> None:
    """The run is over: whatever keeps this interpreter from ending gets a minute."""
    timer = threading.Timer(EXIT_GRACE_S, _end, ("the run is over, but this process did not end",))
    timer.daemon = True
    timer.start()
    _backstop(EXIT_GRACE_S + BACKSTOP_S)


def _backstop(seconds: float) -> None:
    """faulthandler's bound: every thread's stack, then the process's end, ``seconds`` from now."""
    out = sys.__stderr__
    if out is not None:
        faulthandler.dump_traceback_later(seconds, exit=True, file=out)
