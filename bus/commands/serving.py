"""Serving requests on a queryable as a robot's owner serves commands: the request's
arguments checked by the gate, the answer (or the ``CommandError``) as a reply. For
nodes that serve ``<name>/program/<verb>`` (a show, a map node that drives robots)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zenoh

from .. import codec, keys, messages
from ..errors import CommandError
from .validate import error_reply, ok_reply, request_args


def arguments(gate: messages.Gate, query: zenoh.Query, verb: str,
              on_bad: Callable[[], None] = lambda: None, section: str | None = None) -> dict[str, Any]:
    """The request's arguments (``{}`` for none), checked by ``gate`` and, with ``section``, by the
    verb's schema in ``schemas/v1/<section>/`` (``validate.request_args``); ``CommandError``
    ``bad_request`` when either refuses them (``on_bad()`` first, for the gate's refusal)."""
    payload = query.payload.to_bytes() if query.payload is not None else b""
    try:
        if section is not None:
            return request_args(gate, str(query.key_expr), payload, section, verb)
        return gate.check(keys.Key.parse(str(query.key_expr)), payload) if payload else {}
    except CommandError as exc:
        if isinstance(exc.__cause__, messages.BadMessage):
            on_bad()
        raise
    except ValueError as exc:  # messages.BadMessage
        on_bad()
        raise CommandError("bad_request", f"{verb}: {exc}") from None


def answer(query: zenoh.Query, verb: str, result: Callable[[], dict[str, Any]],
           on_refused: Callable[[], None] = lambda: None, key: str | None = None) -> None:
    """Reply to ``query`` with ``result()``, or with the ``CommandError`` it raised (after
    ``on_refused()``); on ``key`` (the node's own, for a query on a pattern), else the query's."""
    try:
        reply = ok_reply(verb, result())
    except CommandError as exc:
        on_refused()
        reply = error_reply(verb, exc)
    query.reply(key or query.key_expr, codec.encode(reply), encoding=codec.ENCODING)
