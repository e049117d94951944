"""Who may use which route: the operator's token, the kiosk's, and this machine alone.

A request carries its token as ``?token=`` or ``Authorization: Bearer <token>``.
Operator routes take the operator token only; kiosk routes take the kiosk token or the
operator's; the shipped code and kiosk images take none. With no token configured
every route is served to this machine alone (the server then listens on loopback:
``WebConfig`` refuses anything else, and a kiosk token without an operator token), and
only under a loopback name: a web site the operator visits that renames itself to
127.0.0.1 (DNS rebinding) is refused. A WebSocket opened by a page of another site
(its ``Origin`` is not this server) is refused too: browsers let any page open one.
A refusal is a 403 with one plain line, counted ``refused``, and warned about once per
client address.
"""

from __future__ import annotations

import hmac
import ipaddress
import logging
from collections.abc import Callable
from typing import NoReturn
from urllib.parse import urlsplit

from aiohttp import web

log = logging.getLogger(__name__)

MAX_WARNED = 1024  # client addresses remembered as warned about (a scan of the LAN must not grow it for ever)


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
        if role != "asset" and not _same_origin(request):
            self._refuse(peer, request, f"a page of another site ({request.headers['Origin'][:80]}) may not "
                                        "open this server's WebSocket")
        if not self.token:  # (no kiosk token either: WebConfig wants the operator's first)
            if not _loopback(peer):
                self._refuse(peer, request, "this server has no token and serves this machine only")
            if not _loopback_name(request.host):
                self._refuse(peer, request, f"this server has no token and answers to loopback names only, "
                                            f"not {request.host[:80]!r} — open http://127.0.0.1:<port>/")
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


def _same_origin(request: web.Request) -> bool:
    """Whether a WebSocket request comes from a page of this server (or from no page:
    a program sends no ``Origin``)."""
    origin = request.headers.get("Origin")
    if origin is None:
        return True
    return urlsplit(origin).netloc.lower() == request.host.lower()


def _loopback_name(host: str) -> bool:
    """Whether a ``Host`` header names this machine by a loopback name or address."""
    name = urlsplit(f"//{host}").hostname or ""
    return name == "localhost" or name.endswith(".localhost") or _loopback(name)


def _loopback(address: str) -> bool:
    try:
        return ipaddress.ip_address(address.split("%")[0]).is_loopback
    except ValueError:  # (a Unix socket, or nothing: not this machine's loopback)
        return False
