"""Reading how nodes are doing: their stats (``bus/stats.py``) off the bus, in one line.

Every node publishes its stats once a second on ``sonibus/stats/<host>/<node>``
and serves the latest there, so ``latest`` asks once and needs no wait.

>>> summary({"rates": {"received": 1234.4, "sent": 1230.0}, "counters": {"dropped": 0, "bad": 2},
...          "latency_ms": {"p50": 0.8, "p99": 2.14}, "process": {"cpu_percent": 12.3, "rss_bytes": 58_000_000}})
'rx 1,234/s tx 1,230/s drop 0 bad 2 p99 2.1 ms cpu 12% 58 MB'
"""

from __future__ import annotations

import threading
from typing import Any

from . import keys, messages
from .node import Bus, Reply


def latest(bus: Bus, timeout: float = 1.0) -> dict[tuple[str, str], dict[str, Any] | str]:
    """The latest stats of every node that answers within ``timeout`` s, by ``(host, node)``;
    stats the gate refuses (``messages``: the ``node_stats`` schema) as the reason, a string."""
    gate, found = messages.Gate(bus.limits), {}
    done = threading.Event()

    def take(reply: Reply) -> None:
        if reply.payload is None:
            return
        key = keys.Key.parse(reply.key)
        host, _, node = key.name.partition("/")
        try:
            found[(host, node)] = gate.check(key, reply.payload)
        except ValueError as exc:  # messages.BadMessage
            found[(host, node)] = f"stats unusable: {exc}"

    bus.ask(keys.NODE_STATS, take, done.set, timeout=timeout, every_answer=True)
    done.wait(timeout + 1.0)
    return found


def summary(stats: dict[str, Any]) -> str:
    """One line of a node's stats: receive and send rates, drops, bad input, p99 latency
    (where the node measures it), errors (if any), the process's CPU and memory, and how many
    times a supervisor restarted it (if it did)."""
    rates, counters = stats.get("rates", {}), stats.get("counters", {})
    parts = [f"rx {rates.get('received', 0):,.0f}/s", f"tx {rates.get('sent', 0):,.0f}/s",
             f"drop {counters.get('dropped', 0):,}", f"bad {counters.get('bad', 0):,}"]
    if counters.get("errors"):
        parts.append(f"err {counters['errors']:,}")
    latency = stats.get("latency_ms")
    if latency:
        parts.append(f"p99 {latency['p99']:.1f} ms")
    process = stats.get("process", {})
    if process:
        parts.append(f"cpu {process['cpu_percent']:.0f}% {process['rss_bytes'] / 1e6:.0f} MB")
        if process.get("restarts"):
            parts.append(f"restarts {process['restarts']:,}")
    return " ".join(parts)
