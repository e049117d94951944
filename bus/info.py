"""Asking robots for ``<robot>/info`` without waiting: sinks call ``ask`` from
their hot path as often as they like; at most one query per robot is sent per
``retry_s``, and each answer is handed to ``on_info`` on a Zenoh thread (which
should only store or enqueue it)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import zenoh

from . import codec, keys
from .node import Bus


class InfoRequests:
    """``ask(robot)``; answers arrive as ``on_info(robot, info)``, bad ones as ``on_error(robot, text)``."""

    def __init__(self, bus: Bus, on_info: Callable[[str, dict[str, Any]], None],
                 on_error: Callable[[str, str], None], retry_s: float = 2.0) -> None:
        self.bus, self.on_info, self.on_error, self.retry_s = bus, on_info, on_error, retry_s
        self._asked: dict[str, float] = {}

    def ask(self, robot: str) -> None:
        now = time.monotonic()
        if now - self._asked.get(robot, -math.inf) < self.retry_s:
            return
        self._asked[robot] = now

        def take(reply: zenoh.Reply) -> None:
            if reply.ok is None:
                return
            try:
                info = codec.decode(reply.ok.payload)
            except codec.DecodeError as exc:
                self.on_error(robot, f"{robot}/info unusable: {exc}")
                return
            self.on_info(robot, info)

        self.bus.session.get(keys.info(robot), handler=take, timeout=self.retry_s)
