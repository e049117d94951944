"""How often threads of this process wake: their voluntary context switches (each a wait that
ended: a poll's timeout, a message, a timer), read from ``/proc/self/task/<tid>/status``. A
count, not a time: what an idle worker costs in wake-ups, whatever the machine's load."""

from __future__ import annotations

import threading
import time
from typing import Any


def switches(thread: threading.Thread) -> int:
    """``thread``'s voluntary context switches so far (0 once it has ended)."""
    try:
        with open(f"/proc/self/task/{thread.native_id}/status") as f:
            return sum(int(line.split()[1]) for line in f if line.startswith("voluntary_ctxt_switches"))
    except (FileNotFoundError, ProcessLookupError):
        return 0


def wakes(threads: list[threading.Thread], seconds: float) -> dict[str, int]:
    """Each of ``threads``' wake-ups over ``seconds`` (by name; several of one name added)."""
    assert threads, "no thread to count"
    before = [switches(t) for t in threads]
    time.sleep(seconds)  # (the window counted: not a wait for something to happen)
    counted: dict[str, int] = {}
    for thread, was in zip(threads, before, strict=True):
        counted[thread.name] = counted.get(thread.name, 0) + switches(thread) - was
    return counted


def named(prefix: str) -> list[threading.Thread]:
    """The live threads whose name starts with ``prefix`` (a node's: ``"<node>:"``)."""
    return [t for t in threading.enumerate() if t.name.startswith(prefix)]


def left_after_stop(node: Any, prefix: str) -> list[str]:
    """The names of ``prefix``'s threads still alive once ``node.stop()`` has returned: none
    when the stop woke each of them (a worker left to its join's timeout is still alive)."""
    workers = named(prefix)
    node.stop()
    return [t.name for t in workers if t.is_alive()]


def calls(waits: dict[str, tuple[Any, str]], seconds: float) -> dict[str, int]:
    """How often each ``owner.<method>`` of ``waits`` (by name) is called over ``seconds``: a
    worker's waits counted where it waits (its queue's ``get``, its event's ``wait``), each a
    wake-up and a new wait. Where a worker's wait is known this is the count to take: ``wakes``
    also counts each time its thread waited for the GIL, and on a loaded machine (CI, 2 cores)
    those made an idle worker's 2 or 3 wake-ups 10 or 12."""
    counts = dict.fromkeys(waits, 0)
    originals = {name: getattr(owner, method) for name, (owner, method) in waits.items()}

    def counting(name: str) -> Any:
        def counted(*args: Any, **kwargs: Any) -> Any:
            counts[name] += 1
            return originals[name](*args, **kwargs)
        return counted

    for name, (owner, method) in waits.items():
        setattr(owner, method, counting(name))
    try:
        time.sleep(seconds)  # (the window counted: not a wait for something to happen)
    finally:
        for name, (owner, method) in waits.items():
            setattr(owner, method, originals[name])
    return counts
