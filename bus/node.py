"""``Bus``: one node's handle on a Zenoh session, the only way adapters talk.

>>> from sonibus.bus import BusConfig, open_session
>>> with open_session(BusConfig(multicast=False)) as session:
...     bus = Bus(session, node="demo")
...     bus.put("pepper/events/hello", {"t": 0.0, "kind": "hello"})
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
from typing import Any

import zenoh

from . import codec, keys
from .messages import Limits
from .queue import SampleQueue


class Bus:
    """Publish, subscribe, serve and ask on the bus, as node ``node`` of ``host``."""

    def __init__(self, session: zenoh.Session, node: str = "", host: str | None = None,
                 limits: Limits | None = None) -> None:
        self.session = session
        self.node = node
        self.host = host or socket.gethostname()
        self.limits = limits or Limits()  # what the gate of each node on this bus lets through

    def for_node(self, node: str) -> Bus:
        return Bus(self.session, node, self.host, self.limits)

    def stream_publisher(self, key: str) -> zenoh.Publisher:
        """A publisher for high-rate data (joint samples, frames): drops under congestion,
        never back-pressures. Not ``express``: batching measured lossless where express
        lost samples on a busy 2-core machine, at no cost in latency (docs/performance.md)."""
        return self.session.declare_publisher(
            key, encoding=codec.ENCODING, congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.DATA_HIGH, express=False)

    def put(self, key: str, message: dict[str, Any]) -> None:
        """Send one message reliably (events: low rate, must not be dropped)."""
        self.session.put(key, codec.encode(message), encoding=codec.ENCODING,
                         congestion_control=zenoh.CongestionControl.BLOCK)

    def subscribe(self, keyexpr: str, maxlen: int = 1024, queue: SampleQueue | None = None,
                  stamped: bool = False, skip: Callable[[str], bool] | None = None,
                  ) -> tuple[zenoh.Subscriber, SampleQueue]:
        """Samples of ``keyexpr`` as ``(key, payload bytes)`` in a bounded queue
        (``(key, payload, time.monotonic_ns())`` of arrival if ``stamped``).

        ``keyexpr`` may use globs inside a chunk (``pepper/joints/R*``); a bad one
        raises ``ConfigError``. Pass ``queue`` to feed several subscriptions into one,
        ``skip`` to leave out the keys it returns True for."""
        keyexpr = keys.expr(keyexpr)
        queue = queue if queue is not None else SampleQueue(maxlen)

        def enqueue(sample: zenoh.Sample) -> None:
            key = str(sample.key_expr)
            if skip is None or not skip(key):
                queue.put((key, sample.payload.to_bytes(), time.monotonic_ns()) if stamped
                          else (key, sample.payload.to_bytes()))

        return self.session.declare_subscriber(keyexpr, enqueue), queue

    def serve(self, keyexpr: str, handler: Callable[[zenoh.Query], None]) -> zenoh.Queryable:
        return self.session.declare_queryable(keyexpr, handler)

    def token(self, key: str) -> zenoh.LivelinessToken:
        return self.session.liveliness().declare_token(key)

    def alive(self, keyexpr: str, timeout: float = 1.0) -> list[str]:
        """Keys of the liveliness tokens alive under ``keyexpr``."""
        replies = self.session.liveliness().get(keyexpr, timeout=timeout)
        return sorted(str(r.ok.key_expr) for r in replies if r.ok is not None)

    def query(self, selector: str, message: dict[str, Any] | None = None,
              timeout: float = 5.0) -> list[dict[str, Any]]:
        """Decoded replies to a query; an empty list when nobody serves ``selector``."""
        payload = codec.encode(message) if message is not None else None
        replies = self.session.get(selector, payload=payload, encoding=codec.ENCODING, timeout=timeout)
        out = []
        for reply in replies:
            if reply.ok is not None:
                out.append(codec.decode(reply.ok.payload))
            else:
                out.append({"ok": False, "error": {"code": "internal",
                                                   "message": reply.err.payload.to_string()}})
        return out

    def __repr__(self) -> str:
        return f"<Bus node={self.node!r} host={self.host!r} zid={self.session.zid()}>"
