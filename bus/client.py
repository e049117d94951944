"""Asking a robot to do something: one query, one reply, a timeout.

``ask`` sends at once and hands the outcome to a callback (the OSC gateway
uses it so that a slow robot never stalls its receive loop; queries leave in
the order they were asked); ``send_command`` waits for it. ``ask_program``
asks the program that drives a robot (a show's ``scenario``) the same way.

>>> send_command(bus, "pepper", "say", {"text": "hello"})   # doctest: +SKIP
{'duration': 0.6, 'queued': 0}
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from . import codec, keys
from .errors import CommandError, RobotNotFound
from .node import Bus, Reply
from .ownership import Claim, claims, owners

Outcome = dict[str, Any] | CommandError


def ask(bus: Bus, robot: str, verb: str, args: dict[str, Any], done: Callable[[Outcome], None],
        timeout: float = 5.0, owner: Claim | None = None) -> None:
    """Send ``verb`` to ``robot``'s ``owner`` alone (default: the earliest claim this
    session has seen, if any; see ``owner_of``); ``done`` gets the result or a
    ``CommandError`` (``robot_not_found``, ``timeout``, or the robot's refusal), exactly once."""
    pending = _Pending(robot, verb, done, timeout)
    owner = owner if owner is not None else owners(bus).owner(robot)
    _send(bus, keys.command(robot, verb) + (f"?owner={owner.address}" if owner is not None else ""), args, pending)


def ask_program(bus: Bus, robot: str, verb: str, args: dict[str, Any], done: Callable[[Outcome], None],
                timeout: float = 5.0) -> None:
    """Send ``verb`` to the program that drives ``robot`` (``<robot>/program/<verb>``: a
    show's ``scenario``) as ``ask`` sends a command: ``done`` gets the result or a
    ``CommandError`` (``program_not_found`` when nothing serves the key), exactly once."""
    key = keys.program(robot, verb)
    nobody = CommandError("program_not_found", f"{verb}: no program drives robot '{robot}' ({key} is served by "
                                               f"nothing) — start the node that does, on the same bus")
    _send(bus, key, args, _Pending(robot, verb, done, timeout, nobody))


def _send(bus: Bus, selector: str, args: dict[str, Any], pending: _Pending) -> None:
    try:
        # Every answer, not one per key: a node standing by for the robot's owner answers too (``conflict``).
        bus.ask(selector, pending.on_reply, pending.on_end, message=args, timeout=pending.timeout, every_answer=True)
    except Exception as exc:  # a closed session, a key Zenoh refuses
        pending.finish(CommandError("internal", f"{pending.verb}: the bus refused the query: {exc}"))


class _Pending:
    """The first answer wins, except a ``conflict`` refusal (a node standing by for the
    robot's owner), which counts only if nothing else answers; a query that ends
    unanswered is ``timeout`` when it lasted about ``timeout`` (Zenoh then reports
    "Timeout" as an error reply), else ``robot_not_found`` (nobody serves the key: it
    ends at once)."""

    def __init__(self, robot: str, verb: str, done: Callable[[Outcome], None], timeout: float,
                 nobody: CommandError | None = None) -> None:
        self.robot, self.verb, self.done, self.timeout = robot, verb, done, timeout
        self.nobody = nobody or RobotNotFound(robot)  # what an answer that ends at once, unanswered, means
        self.started = time.monotonic()
        self.error = ""
        self.standing_by: CommandError | None = None
        self._finished = False
        self._lock = threading.Lock()

    def on_reply(self, reply: Reply) -> None:
        if reply.payload is None:
            self.error = reply.error
            return
        try:
            message = codec.decode(reply.payload)
        except codec.DecodeError as exc:
            message = {"ok": False, "error": {"code": "internal", "message": f"{self.verb}: bad reply: {exc}"}}
        if message.get("ok") is True:
            self.finish(message.get("result") or {})
            return
        error = message.get("error") or {}
        refusal = CommandError(str(error.get("code", "internal")),
                               str(error.get("message", f"robot '{self.robot}' refused '{self.verb}'")))
        if refusal.code == "conflict":
            self.standing_by = refusal
        else:
            self.finish(refusal)

    def on_end(self) -> None:
        if self.standing_by is not None:
            self.finish(self.standing_by)
        elif time.monotonic() - self.started >= self.timeout * 0.9:
            self.finish(CommandError("timeout", f"robot '{self.robot}' did not answer '{self.verb}' "
                                                f"within {self.timeout:g} s"))
        elif self.error:
            self.finish(CommandError("internal", f"{self.verb}: {self.error}"))
        else:
            self.finish(self.nobody)

    def finish(self, outcome: Outcome) -> None:
        with self._lock:
            if self._finished:
                return
            self._finished = True
        self.done(outcome)


def send_command(bus: Bus, robot: str, verb: str, args: dict[str, Any] | None = None,
                 timeout: float = 5.0, owner: Claim | None = None) -> dict[str, Any]:
    """The result of ``verb`` on ``robot`` (run by its ``owner`` alone, if given), or
    ``CommandError`` (``RobotNotFound`` when no node owns the robot, code ``timeout``
    when it did not answer)."""
    answered = threading.Event()
    outcomes: list[Outcome] = []

    def done(outcome: Outcome) -> None:
        outcomes.append(outcome)
        answered.set()

    ask(bus, robot, verb, args or {}, done, timeout, owner)
    if not answered.wait(timeout + 1.0):
        raise CommandError("timeout", f"robot '{robot}' did not answer '{verb}' within {timeout:g} s")
    if isinstance(outcomes[0], CommandError):
        raise outcomes[0]
    return outcomes[0]


def owner_of(bus: Bus, robot: str, timeout: float = 2.0) -> Claim | None:
    """The owner of ``robot`` as this node sees it (the earliest claim), waiting up to
    ``timeout`` for one (a process that has just joined may not have found its peers
    yet); None if none came. A command sent to it alone runs once even
    while two owners of the robot have not yet seen each other."""
    deadline = time.monotonic() + timeout
    while True:
        found = claims(bus.alive(keys.robot_token(robot), timeout=0.25)).get(robot)
        if found:
            return found[0]
        if time.monotonic() >= deadline:
            return None


def robot_info(bus: Bus, robot: str, timeout: float = 2.0) -> dict[str, Any] | None:
    """The robot's description from ``<robot>/info``, or None if nobody serves it."""
    replies = bus.query(keys.info(robot), timeout=timeout)
    return replies[0] if replies else None
