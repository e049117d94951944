"""Serving requests on a queryable as a robot's owner serves commands: the request's
arguments checked by the gate, the answer (or the ``CommandError``) as a reply. For
nodes that serve ``<name>/program/<verb>`` (a show, a map node that drives robots)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zenoh

from .. import codec, keys, messages
from ..errors import CommandError
from .validate import error_reply, ok_reply


def arguments(gate: messages.Gate, query: zenoh.Query, verb: str,
              on_bad: Callable[[], None] = lambda: None) -> dict[str, Any]:
    """The request's arguments (``{}`` for none), checked by ``gate``; ``CommandError``
    ``bad_request`` (after ``on_bad()``) when it refuses them."""
    payload = query.payload.to_bytes() if query.payload is not None else b""
    try:
        return gate.check(keys.Key.parse(str(query.key_expr)), payload) if payload else {}
    except ValueError as exc:  # messages.BadMessage
        on_bad()
        raise CommandError("bad_request", f"{verb}: {exc}") from None


def answer(query: zenoh.Query, verb: str, result: Callable[[], dict[str, Any]],
           on_refused: Callable[[], None] = lambda: None) -> None:
    """Reply to ``query`` with ``result()``, or with the ``CommandError`` it raised (after ``on_refused()``)."""
    try:
        reply = ok_reply(verb, result())
    except CommandError as exc:
        on_refused()
        reply = error_reply(verb, exc)
    query.reply(query.key_expr, codec.encode(reply), encoding=codec.ENCODING)
