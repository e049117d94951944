"""Asking a robot to do something: one query, one reply, a timeout.

``ask`` sends at once and hands the outcome to a callback (the OSC gateway
uses it so that a slow robot never stalls its receive loop; queries leave in
the order they were asked); ``send_command`` waits for it. ``ask_program``
asks the program that drives a robot (a show's ``scenario``) the same way.
``stop_all`` stops every robot of the bus with one query, whatever their number.

>>> send_command(bus, "pepper", "say", {"text": "hello"})   # doctest: +SKIP
{'duration': 0.6, 'queued': 0}
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

from . import codec, keys
from .claimwatch import owners
from .errors import CommandError, RobotNotFound
from .node import Bus, Reply
from .ownership import MAX_ROBOTS, Claim, claims

Outcome = dict[str, Any] | CommandError
STOP_ALL = keys.command("*", "stop")  # one query every owner of the bus serves: no robot waits behind another

UNANSWERED = ("timeout", "not_connected", "not_answering")
"""Codes of a command the robot did not carry out because it could not be reached:
``timeout`` (no reply in time: this module's), ``not_connected`` and ``not_answering``
(the owner's: its robot is not connected, or does not answer; ``bus/connection.py``).
``sonibus send`` exits 5 for them, as for a ``stop`` whose result says ``reached: false``."""


def unreached(result: dict[str, Any]) -> bool:
    """Whether a command's result says it did not reach the robot (a ``stop`` is never
    refused: it is taken, and says so).

    >>> unreached({"reached": False, "connection": "lost"}), unreached({})
    (True, False)
    """
    return result.get("reached") is False


def ask(bus: Bus, robot: str, verb: str, args: dict[str, Any], done: Callable[[Outcome], None],
        timeout: float = 5.0, owner: Claim | None = None) -> None:
    """Send ``verb`` to ``robot``'s ``owner`` alone (default: the earliest claim this
    session has seen, if any; see ``owner_of``); ``done`` gets the result or a
    ``CommandError`` (``robot_not_found``, ``timeout``, or the owner's refusal:
    ``not_connected``, ``not_answering``, ``bad_request``...), exactly once."""
    pending = _Pending(robot, verb, done, timeout)
    owner = owner if owner is not None else owners(bus).owner(robot)
    parameters = [f"owner={owner.address}"] if owner is not None else []
    if verb == "stop":  # (served on both sessions of its owner: its id has it run once)
        parameters.append(f"id={uuid.uuid4().hex}")
    # (Zenoh's parameters are separated by ';': with '&' the id was read as part of the owner)
    _send(bus, keys.command(robot, verb) + ("?" + ";".join(parameters) if parameters else ""), args, pending,
          urgent=verb == "stop")


def ask_program(bus: Bus, robot: str, verb: str, args: dict[str, Any], done: Callable[[Outcome], None],
                timeout: float = 5.0) -> None:
    """Send ``verb`` to the program that drives ``robot`` (``<robot>/program/<verb>``: a
    show's ``scenario``) as ``ask`` sends a command: ``done`` gets the result or a
    ``CommandError`` (``program_not_found`` when nothing serves the key), exactly once."""
    key = keys.program(robot, verb)
    nobody = CommandError("program_not_found", f"{verb}: no program drives robot '{robot}' ({key} is served by "
                                               f"nothing) — start the node that does, on the same bus")
    ask_key(bus, key, args, done, timeout, nobody)


def ask_key(bus: Bus, key: str, args: dict[str, Any], done: Callable[[Outcome], None], timeout: float,
            nobody: CommandError, who: str = "") -> None:
    """Send a request to whatever serves ``key`` (``<robot>/program/<verb>``, a map node's
    ``<node>/maps/<verb>``), answered as a command is: ``done`` gets the result or a
    ``CommandError`` (``nobody`` when nothing serves the key; ``timeout`` naming ``who``, by
    default the robot of the key's first chunk), exactly once."""
    name, _, rest = key.partition("/")
    _send(bus, key, args, _Pending(name, rest.partition("/")[2], done, timeout, nobody, who))


def _send(bus: Bus, selector: str, args: dict[str, Any], pending: _Pending, urgent: bool = False) -> None:
    try:
        # Every answer, not one per key: a node standing by for the robot's owner answers too (``conflict``).
        bus.ask(selector, pending.on_reply, pending.on_end, message=args, timeout=pending.timeout, every_answer=True,
                urgent=urgent)
    except Exception as exc:  # a closed session, a key Zenoh refuses
        pending.finish(CommandError("internal", f"{pending.verb}: the bus refused the query: {exc}"))


class _Pending:
    """The first answer wins, except a ``conflict`` refusal (a node standing by for the
    robot's owner), which counts only if nothing else answers; a query that ends
    unanswered is ``timeout`` when it lasted about ``timeout`` (Zenoh then reports
    "Timeout" as an error reply), else ``robot_not_found`` (nobody serves the key: it
    ends at once)."""

    def __init__(self, robot: str, verb: str, done: Callable[[Outcome], None], timeout: float,
                 nobody: CommandError | None = None, who: str = "") -> None:
        self.robot, self.verb, self.done, self.timeout = robot, verb, done, timeout
        self.who = who or f"robot '{robot}'"  # (in a timeout's message)
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
        outcome = _outcome(reply.payload, self.robot, self.verb)
        if isinstance(outcome, CommandError) and outcome.code == "conflict":
            self.standing_by = outcome
        else:
            self.finish(outcome)

    def on_end(self) -> None:
        if self.standing_by is not None:
            self.finish(self.standing_by)
        elif time.monotonic() - self.started >= self.timeout * 0.9:
            self.finish(CommandError("timeout", f"{self.who} did not answer '{self.verb}' within {self.timeout:g} s"))
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


def stop_all(bus: Bus, done: Callable[[str, Outcome], None], silent: Callable[[list[str], CommandError], None],
             timeout: float = 5.0) -> None:
    """Stop every robot of this bus (of its namespace: this installation) at once: one query
    on ``*/cmd/stop`` reaches every owner together (a robot owner runs ``stop`` whatever its
    claim state), so its time does not grow with the number of robots, nor with claims
    that no owner stands behind. ``done(robot, outcome)`` for each robot that answered (its
    first answer; at most ``MAX_ROBOTS``), then ``silent(robots, error)`` once, when the
    query is over, with the robots on the bus (their claims seen) that did not answer (maybe
    none): ``robot_not_found`` when the query ended at once (nothing serves their commands),
    ``timeout`` after ``timeout``."""
    answered: set[str] = set()
    lock = threading.Lock()
    started = time.monotonic()
    on_bus = owners(bus)  # (made before the query: the robots it knows when the query ends)

    def on_reply(reply: Reply) -> None:
        robot = reply.key.partition("/")[0]
        if reply.payload is None or keys.command_verb(reply.key) != "stop" or not keys.is_concrete(robot):
            return  # (Zenoh's own error reply, or an answer naming no robot: nothing to report it under)
        with lock:
            if robot in answered or len(answered) >= MAX_ROBOTS:
                return
            answered.add(robot)
        done(robot, _outcome(reply.payload, robot, "stop"))

    def on_end() -> None:
        with lock:
            left = [robot for robot in on_bus.robots() if robot not in answered]
        if time.monotonic() - started >= timeout * 0.9:
            error = CommandError("timeout", f"no answer within {timeout:g} s")
        else:
            error = CommandError("robot_not_found", "nothing serves their commands: a claim without an owner "
                                                    "that answers (a node still connecting, or one made up)")
        silent(left, error)

    try:
        bus.ask(f"{STOP_ALL}?id={uuid.uuid4().hex}", on_reply, on_end, message={}, timeout=timeout,
                every_answer=True, urgent=True)
    except Exception as exc:  # a closed session
        silent(on_bus.robots(), CommandError("internal", f"the bus refused the query: {exc}"))


def _outcome(payload: bytes, robot: str, verb: str) -> Outcome:
    """A reply's payload as a result, or the robot's refusal (``CommandError``)."""
    try:
        message = codec.decode(payload)
    except codec.DecodeError as exc:
        return CommandError("internal", f"{verb}: bad reply: {exc}")
    if not isinstance(message, dict):
        return CommandError("internal", f"{verb}: bad reply: not a map")
    if message.get("ok") is True:
        return message.get("result") or {}
    error = message.get("error") or {}
    return CommandError(str(error.get("code", "internal")), str(error.get("message", f"robot '{robot}' refused "
                                                                                       f"'{verb}'")))


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
