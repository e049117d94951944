"""Asking a robot to do something: one query, one reply, a timeout.

>>> send_command(bus, "pepper", "say", {"text": "hello"})   # doctest: +SKIP
{'text': 'hello'}
"""

from __future__ import annotations

import time
from typing import Any

from . import keys
from .errors import CommandError, RobotNotFound
from .node import Bus


def send_command(bus: Bus, robot: str, verb: str, args: dict[str, Any] | None = None,
                 timeout: float = 5.0) -> dict[str, Any]:
    """The result of ``verb`` on ``robot``, or ``CommandError`` (``RobotNotFound``
    when no node owns the robot)."""
    started = time.monotonic()
    replies = bus.query(keys.command(robot, verb), args or {}, timeout=timeout)
    if not replies:
        if time.monotonic() - started >= timeout * 0.9:
            raise CommandError("timeout", f"robot '{robot}' did not answer '{verb}' within {timeout:g} s")
        raise RobotNotFound(robot)
    reply = replies[0]
    if reply.get("ok") is True:
        return reply.get("result") or {}
    error = reply.get("error") or {}
    raise CommandError(str(error.get("code", "internal")),
                       str(error.get("message", f"robot '{robot}' refused '{verb}'")))


def robot_info(bus: Bus, robot: str, timeout: float = 2.0) -> dict[str, Any] | None:
    """The robot's description from ``<robot>/info``, or None if nobody serves it."""
    replies = bus.query(keys.info(robot), timeout=timeout)
    return replies[0] if replies else None
