"""The WebSocket protocol of the web pages: what a client may send, read strictly, and
the messages the server sends (docs/web.md, "Protocol").

>>> parse('{"type": "command", "id": 7, "robot": "pepper", "verb": "say", "args": {"text": "hi"}}')
Command(id=7, robot='pepper', verb='say', args={'text': 'hi'})
>>> parse('{"type": "stop", "id": 8}')
Stop(id=8)
>>> parse('{"type": "map", "id": 10, "node": "sound", "verb": "undo", "args": {"map": "cutoff"}}')
MapRequest(id=10, node='sound', verb='undo', args={'map': 'cutoff'})
>>> try:
...     parse('{"type": "dance", "id": 9}')
... except BadMessage as exc:
...     print(exc.id, exc)
9 unknown message type 'dance' — a page sends command, stop, map or press
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from sonibus.bus import keys, messages
from sonibus.bus.errors import CommandError

MAX_MESSAGE = 64 * 1024  # characters of one client message; longer ones are refused (the connection stays)
TYPES = ("command", "stop", "map", "press")
RESUME = "resume"  # a map node's <node>/program/resume: its maps drive their robots again after a stop
# what a map node serves (schemas/v1/maps/; resume: its program)
MAP_VERBS = ("list", "edit", "learn", "undo", "save", "add", "remove", RESUME)

Id = int | str | None  # the client's own request id, echoed in the reply


@dataclass(frozen=True)
class Command:
    """Operator: run ``verb`` on ``robot`` with ``args`` (shaped later by ``commands.from_json``)."""

    id: Id
    robot: str
    verb: str
    args: Any


@dataclass(frozen=True)
class Stop:
    """Operator: stop every robot on the bus."""

    id: Id


@dataclass(frozen=True)
class Press:
    """Kiosk: a visitor pressed ``button``."""

    id: Id
    button: str


@dataclass(frozen=True)
class MapRequest:
    """Operator: ``verb`` (edit, learn, undo, save) to map node ``node``'s maps (``<node>/maps/<verb>``),
    or ``resume`` (``<node>/program/resume``)."""

    id: Id
    node: str
    verb: str
    args: Any


Request = Command | Stop | MapRequest | Press


class BadMessage(ValueError):
    """A client message that cannot be taken; ``id`` is its id when it had a usable one."""

    def __init__(self, message: str, id: Id = None) -> None:
        super().__init__(message)
        self.id = id


def parse(text: str) -> Request:
    """The request ``text`` stands for, or ``BadMessage`` saying what is wrong, in one line."""
    if len(text) > MAX_MESSAGE:
        raise BadMessage(f"a message of {len(text):,} characters (at most {MAX_MESSAGE:,})")
    try:
        message = json.loads(text, parse_constant=_NotJson)
    except (ValueError, RecursionError) as exc:
        raise BadMessage(f"not JSON: {str(exc).splitlines()[0][:80]}") from None
    if not isinstance(message, dict):
        raise BadMessage(f"a message must be a JSON object, got {type(message).__name__}")
    raw_id = message.get("id")
    id_: Id = raw_id if isinstance(raw_id, str | int) and not isinstance(raw_id, bool | _NotJson) else None
    if isinstance(id_, str):
        id_ = id_[:64]
    constant = _not_json(message)
    if constant:
        raise BadMessage(f"{constant} is not a JSON number: JSON carries finite numbers only", id_)
    kind = message.get("type")
    if kind not in TYPES:
        raise BadMessage(f"unknown message type {str(kind)[:40]!r} — a page sends {', '.join(TYPES[:-1])} "
                         f"or {TYPES[-1]}", id_)
    if kind == "stop":
        return Stop(id_)
    if kind == "press":
        return Press(id_, _name(message, "button", id_))
    if kind == "map":
        node, verb = _name(message, "node", id_), _name(message, "verb", id_)
        try:
            keys.check_name("node", node)
        except ValueError as exc:
            raise BadMessage(f"map: {exc}", id_) from None
        if verb not in MAP_VERBS:
            raise BadMessage(f"map: unknown verb {verb[:40]!r} — a map node takes {', '.join(MAP_VERBS)}", id_)
        args = message.get("args", {})
        if not isinstance(args, dict):
            raise BadMessage("map: 'args' must be an object", id_)
        return MapRequest(id_, node, verb, args)
    robot, verb = _name(message, "robot", id_), _name(message, "verb", id_)
    try:
        for chunk in (robot, *verb.split("/")):
            keys.check_name("robot" if chunk == robot else "verb", chunk)
    except ValueError as exc:
        raise BadMessage(f"command: {exc}", id_) from None
    return Command(id_, robot, verb, message.get("args", {}))


class _NotJson(str):
    """``NaN``, ``Infinity`` or ``-Infinity`` where a page sent it: Python's reader takes them,
    JSON has none, and a NaN angle must not even be held as a slider move (it was answered
    ``coalesced``). Kept as a marker so the refusal can carry the message's id."""


def _not_json(value: Any) -> str:
    """The first ``_NotJson`` constant in ``value`` ("" if none); a loop, not a recursion (a
    message nested as deep as the JSON reader allows must not overflow the stack here)."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, _NotJson):
            return str(item)
        if isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
    return ""


def _name(message: dict[str, Any], field: str, id_: Id) -> str:
    value = message.get(field)
    if not isinstance(value, str) or not value:
        raise BadMessage(f"{message['type']}: '{field}' must be a non-empty string", id_)
    return value[:200]


def reply(id_: Id, outcome: dict[str, Any] | CommandError | str, robot: str = "") -> dict[str, Any]:
    """The ``reply`` to request ``id_``: a result (refused if JSON cannot carry it), or a
    refusal (a ``CommandError``'s line, or the text of one)."""
    message: dict[str, Any] = {"type": "reply", "id": id_}
    if robot:
        message["robot"] = robot
    if isinstance(outcome, dict):
        try:  # (a reply does not pass the gate on its way: a NaN would end the server's loop, every page with it)
            messages.json_like(outcome, "result")
        except messages.BadMessage as exc:
            return {**message, "ok": False, "error": f"the robot answered, but its reply cannot be shown: {exc}"}
        return {**message, "ok": True, "result": outcome}
    error = outcome.message if isinstance(outcome, CommandError) else outcome
    return {**message, "ok": False, "error": " ".join(str(error).split())}  # one line, whatever came


SILENT_NAMED = 10  # robots a stop's reply names in its text (``robots`` has them all)


def silent(id_: Id, robots: list[str], error: CommandError) -> dict[str, Any]:
    """The last ``reply`` of a stop: the robots on the bus that did not answer it, and why
    (``robots``: their names; one reply for all, however many they are)."""
    named = ", ".join(robots[:SILENT_NAMED]) + (f", … ({len(robots)} in all)" if len(robots) > SILENT_NAMED else "")
    return {"type": "reply", "id": id_, "ok": False, "robots": robots,
            "error": f"stop: {len(robots)} robot(s) on the bus did not answer ({error.message}): {named}"}
