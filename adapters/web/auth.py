"""Who may use which route: the operator's token, the kiosk's, and this machine alone.

A request carries its token as ``?token=`` or ``Authorization: Bearer <token>``.
Operator routes take the operator token only; kiosk routes take the kiosk token or the
operator's; the shipped code and kiosk images take none. With no token configured
every route is served to this machine alone (the server then listens on loopback:
``WebConfig`` refuses anything else, and a kiosk token without an operator token).
A refusal is a 403 with one plain line, counted ``refused``, and warned about once per
client address.

Pages of other sites (``Origin``) and names that are not this server's (``Host``: DNS
rebinding) are refused before the token is looked at, by the rule of every server
(``bus/browser.py``, run by ``WebServer``): ``names`` says which names this node answers to.
"""

from __future__ import annotations

import hmac
import logging
from collections.abc import Callable
from typing import NoReturn

from aiohttp import web

from sonibus.bus.browser import ANY, LOOPBACK, loopback_address

log = logging.getLogger(__name__)

MAX_WARNED = 1024  # client addresses remembered as warned about (a scan of the LAN must not grow it for ever)


def names(token: str) -> str:
    """The ``Host`` names a web node answers to: with a token any (a site that renamed itself
    to this machine's address does not have it), without one loopback names only."""
    return ANY if token else LOOPBACK


class Guard:
    """Checks requests against ``token`` (operator) and ``kiosk_token``; ``refused(address,
    reason)`` is told of every refusal (the adapter counts it)."""

    def __init__(self, token: str, kiosk_token: str, node: str, count: Callable[[str], None]) -> None:
        self.token, self.kiosk_token, self.node, self.count = token, kiosk_token, node, count
        self._warned: set[str] = set()

    def check(self, request: web.Request, role: str) -> None:
        """Return if ``request`` may use a route of ``role`` ("operator", "kiosk", or "asset":
        shipped files and kiosk images, public where a token is configured); else raise a 403."""
        peer = request.remote or ""
        if not self.token:  # (no kiosk token either: WebConfig wants the operator's first)
            if not loopback_address(peer):
                self._refuse(peer, request, "this server has no token and serves this machine only")
            return
        if role == "asset":  # the shipped code and kiosk images: no secret, and a page cannot pass tokens on
            return
        given = _token(request)
        if given is None:
            self._refuse(peer, request, "a token is needed (?token=... or Authorization: Bearer ...)")
        accepted = (self.token, self.kiosk_token) if role == "kiosk" and self.kiosk_token else (self.token,)
        if not any(_same(given, t) for t in accepted):
            self._refuse(peer, request, "wrong token for this page")

    def _refuse(self, peer: str, request: web.Request, reason: str) -> NoReturn:
        self.count("refused")
        if peer not in self._warned:
            if len(self._warned) >= MAX_WARNED:
                self._warned.clear()
            self._warned.add(peer)
            log.warning("%s: refused %s %s from %s: %s (said once per address)", self.node, request.method,
                        request.path, peer or "an unknown address", reason)
        raise web.HTTPForbidden(text=f"403 forbidden: {reason}\n")


def _token(request: web.Request) -> str | None:
    if "token" in request.query:
        return request.query["token"]
    scheme, _, value = request.headers.get("Authorization", "").partition(" ")
    return value.strip() if scheme.lower() == "bearer" else None


def _same(given: str, token: str) -> bool:
    return hmac.compare_digest(given.encode(), token.encode())
