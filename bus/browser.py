"""Who may read a server from a web browser: the ``Origin`` and ``Host`` rule of every
server on ``bus/web.py`` (the web pages, OSCQuery, Foxglove), in one place.

Browsers let any page open a WebSocket to any address, and send the page's ``Origin``
with it; a web site can also rename itself to this machine's address (DNS rebinding) and
then read it as its own, under its own name in ``Host``. So a request is refused when its
``Origin`` is a page of another site (not this server, not in the node's ``origins``) or
when its ``Host`` is not a name this server answers to (``names``):

- ``OWN``: a name of this machine: an address, ``localhost``, a ``.local`` name (mDNS), its
  host name (OSCQuery and Foxglove, which have no token);
- ``LOOPBACK``: a loopback name or address only (the web node without a token: it serves
  this machine alone);
- ``ANY``: any (the web node with a token: a page of a renamed site does not have it).

Programs send no ``Origin`` and pass.

>>> own_name("127.0.0.1:8080"), own_name("[::1]:80"), own_name("robots.local"), own_name("evil.example")
(True, True, True, False)
>>> loopback_name("localhost:8080"), loopback_name("[::1]"), loopback_name("192.168.1.4:8080")
(True, True, False)
"""

from __future__ import annotations

import ipaddress
import socket
from urllib.parse import urlsplit

from aiohttp import web

from .text import printable

OWN, LOOPBACK, ANY = "own", "loopback", "any"


def check_browser(request: web.Request, origins: tuple[str, ...] = (), names: str = OWN) -> str:
    """Why ``request`` may come from a web page that must not read this server ("" if none):
    an ``Origin`` that is not this server nor in ``origins`` (``"*"``: any), or a ``Host``
    that is not one of ``names`` (``OWN``, ``LOOPBACK``, ``ANY``)."""
    origin = request.headers.get("Origin")
    if origin is not None and _netloc(origin) != request.host.lower() and origin not in origins \
            and "*" not in origins:
        return (f"a page of another site ({_shown(origin)}) may not read this server (a site to let in goes in the "
                "node's `origins`)" if origins else f"a page of another site ({_shown(origin)}) may not read this "
                "server")
    if names == ANY or "Host" not in request.headers:
        return ""
    if names == LOOPBACK and not loopback_name(request.host):
        return (f"this server answers to loopback names only, not '{_shown(request.host)}' (a web site that renames "
                "itself to this address?) — open http://127.0.0.1:<port>/")
    if names == OWN and not own_name(request.host):
        return (f"'{_shown(request.host)}' is not a name of this machine (a web site that renames itself to this "
                "address?) — open it by its address or host name")
    return ""


def _shown(text: str) -> str:
    """At most 80 characters of a header, safe to log and to answer with (a header that is not
    UTF-8 comes with surrogates, which an answer cannot encode: 500)."""
    return printable(text[:80].encode("utf-8", "backslashreplace").decode("utf-8"))


def _netloc(origin: str) -> str | None:
    """The ``host:port`` of an ``Origin``, None if it does not parse (``http://[x``)."""
    try:
        return urlsplit(origin).netloc.lower()
    except ValueError:
        return None


def _name(host: str) -> str:
    """The name in a ``Host`` header ("" if it does not parse: ``[::1``)."""
    try:
        return (urlsplit(f"//{host}").hostname or "").rstrip(".")
    except ValueError:
        return ""


def own_name(host: str) -> bool:
    """Whether a ``Host`` header names this machine: an address, ``localhost``, a ``.local``
    name, or its host name."""
    name = _name(host)
    if name == "localhost" or name.endswith((".localhost", ".local")):
        return True
    try:
        ipaddress.ip_address(name.split("%")[0])
        return True
    except ValueError:
        pass
    mine = socket.gethostname().lower()
    return name in (mine, mine.partition(".")[0])


def loopback_name(host: str) -> bool:
    """Whether a ``Host`` header names this machine by a loopback name or address."""
    name = _name(host)
    return name == "localhost" or name.endswith(".localhost") or loopback_address(name)


def loopback_address(address: str) -> bool:
    """Whether ``address`` (an IP, maybe with an IPv6 zone) is a loopback address; a name,
    a Unix socket or nothing is not."""
    try:
        return ipaddress.ip_address(address.split("%")[0]).is_loopback
    except ValueError:
        return False
