"""OSCQuery over HTTP and WebSocket on one port, on ``bus/web.py``'s ``WebServer``.

``GET /path`` answers the node's JSON, ``GET /path?ATTR`` ``{"ATTR": ...}`` (204 when
the node lacks it, 400 for an attribute the spec does not name), ``GET /?HOST_INFO``
the host's description; 404 for a path that is not served. A WebSocket on the same
port takes the same queries as text (``/path?ATTR``, answered as text, as libossia's
clients ask) and ``{"COMMAND": "LISTEN"|"IGNORE", "DATA": path}``: a listened path's values
go to that client as binary OSC messages, and every client hears ``PATH_ADDED``,
``PATH_REMOVED`` and ``PATH_CHANGED`` (``{"COMMAND": ..., "DATA": path}``).

Within the ``WebServer``'s limits (connections, clients, timeouts) and its browser
check (a page of another site, or a name that is not this machine's, gets 403: a web
page the operator opens must not read the robots' values). A client may listen to
``MAX_LISTENS`` paths, of which ``MAX_UNSERVED`` not served (yet): a path the namespace
serves is held once (interned) whoever listens, so clients cost little and give it back.
"""

from __future__ import annotations

import contextlib
import functools
import json
import re
import sys
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from aiohttp import WSMessage, WSMsgType, web

from sonibus.adapters.foxglove.framed import FramedClient
from sonibus.adapters.foxglove.wire import BINARY, frame_header
from sonibus.bus.web import WebServer, close_clients

from .live import Live

if TYPE_CHECKING:
    from sonibus.bus.adapter import Adapter

ATTRIBUTES = frozenset({"FULL_PATH", "CONTENTS", "TYPE", "ACCESS", "VALUE", "RANGE", "DESCRIPTION", "UNIT",
                        "TAGS", "CLIPMODE", "EXTENDED_TYPE", "CRITICAL", "OVERLOADS", "HOST_INFO"})
MAX_WS_TEXT = 4096        # characters of one client command; longer ones are refused (counted as bad)
MAX_WS_MESSAGE = 1 << 20  # bytes; aiohttp closes a connection that sends more in one message (code 1009)
MAX_LISTENS = 4096        # paths one client may listen to
MAX_UNSERVED = 64         # of which not served when LISTENed (each held for that client alone)
MAX_ADDRESS = 1024        # characters of a LISTENed path
HEARTBEAT_S = 10.0        # a ping this often; a client that does not answer within half of it is dropped
# A LISTENed path: printable ASCII without space or '#' (OSC reserves it for bundles); no control character
# reaches the operator's terminal through a warning.
_OSC_ADDRESS = re.compile(rf"/[!-\"$-~]{{0,{MAX_ADDRESS - 1}}}")
_dumps = functools.partial(json.dumps, allow_nan=False)  # (NaN is no JSON: a client's parser refuses it)


class QueryServer:
    """The OSCQuery routes of ``web`` (a started ``WebServer`` serves them), answering from
    ``live``; ``host_info`` is the ``/?HOST_INFO`` object. ``send_osc`` and ``announce``
    may be called from any thread."""

    def __init__(self, adapter: Adapter, web_server: WebServer, live: Live, host_info: dict[str, Any]) -> None:
        self.adapter, self.web, self.live, self.host_info = adapter, web_server, live, host_info
        self.listened: dict[str, int] = {}  # path → how many clients listen (read from other threads)
        self._clients: set[_Client] = set()
        web_server.app.router.add_get("/{path:.*}", self.get)
        web_server.app.on_shutdown.append(self._close_all)

    @property
    def clients(self) -> int:
        return len(self._clients)

    # -- from any thread -------------------------------------------------------------

    def send_osc(self, messages: list[tuple[str, bytes]]) -> None:
        """Send each ``(path, OSC message)`` to the clients that listen to ``path``."""
        self.web.call(self._send_osc, messages)

    def announce(self, command: str, path: str) -> None:
        """Tell every client ``{"COMMAND": command, "DATA": path}``."""
        self.web.call(self._push_all, _dumps({"COMMAND": command, "DATA": path}))

    # -- on the loop -----------------------------------------------------------------

    async def get(self, request: web.Request) -> web.StreamResponse:
        if web.WebSocketResponse().can_prepare(request).ok:
            return await self._websocket(request)
        self.adapter.count("http_requests")
        status, answer = self.answer("/" + request.match_info["path"], request.query_string)
        if status != 200:
            return web.Response(status=status, text=answer and f"{answer}\n")
        return web.json_response(answer, dumps=_dumps)

    def answer(self, path: str, attribute: str = "") -> tuple[int, Any]:
        """``(200, JSON object)`` for ``path`` (and ``?attribute``; ``?VALUE`` before a first value:
        ``{}``), else ``(status, reason)``: 404 for a path not served, 400 for an attribute the
        spec does not name, 204 for one the node lacks."""
        path = "/" + path.strip("/")
        if attribute == "HOST_INFO":
            return 200, self.host_info
        node = self.live.node(path)
        if node is None:
            return 404, f"no OSC node at {path}"
        if not attribute:
            return 200, node
        if attribute not in ATTRIBUTES:
            return 400, f"unknown attribute {attribute!r}: OSCQuery names {', '.join(sorted(ATTRIBUTES))}"
        if attribute not in node or (attribute == "VALUE" and node.get("ACCESS") != 1):
            return 204, ""  # (a write-only method's VALUE is only a placeholder)
        if attribute == "VALUE" and all(v is None for v in node["VALUE"]):
            return 200, {}  # no value yet
        return 200, {attribute: node[attribute]}

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        async with self.web.accept(request, max_msg_size=MAX_WS_MESSAGE, heartbeat=HEARTBEAT_S,
                                   compress=False) as ws:  # (frames written as they are: FramedClient)
            client = _Client(ws, request, self.adapter)
            self._clients.add(client)
            self.adapter.count("ws_clients")
            try:
                await self.web.serve_client(ws, client, lambda message: self._receive(client, message))
            finally:
                self._clients.discard(client)
                self._ignore(client, list(client.listens))
        return ws

    def _receive(self, client: _Client, message: WSMessage) -> None:
        if message.type == WSMsgType.TEXT:
            self._command(client, message.data)
        elif message.type == WSMsgType.BINARY:
            self._bad(f"a binary WebSocket message of {len(message.data)} bytes (values are set through the "
                      "gateway's UDP port, OSC_PORT in HOST_INFO)")

    def _command(self, client: _Client, text: str) -> None:
        if len(text) > MAX_WS_TEXT:
            self._bad(f"a WebSocket message of {len(text)} characters (at most {MAX_WS_TEXT})")
            return
        if text.startswith("/"):  # a query, as libossia's clients send them: the answer comes as text
            path, _, attribute = text.partition("?")
            status, answer = self.answer(path, attribute)
            if status == 200:
                client.push(_dumps(answer))
            else:
                self._bad(f"the query {text[:80]!r}: {answer or 'no such attribute on that node'}")
            return
        command = None
        if text.strip().startswith("{"):  # (a deep "[[[..." is no command: never handed to the parser)
            with contextlib.suppress(ValueError, RecursionError):
                command = json.loads(text)
        if not isinstance(command, dict):
            self._bad(f"a WebSocket message that is not a JSON object: {text[:60]!r}")
            return
        name, path = command.get("COMMAND"), command.get("DATA")
        if name not in ("LISTEN", "IGNORE") or not isinstance(path, str):
            self._bad(f"a WebSocket command that is not {{\"COMMAND\": \"LISTEN\"|\"IGNORE\", \"DATA\": "
                      f"\"/path\"}}: {text[:80]!r}")
            return
        if not _OSC_ADDRESS.fullmatch(path):
            self._bad(f"{name} {path[:80]!r}: not an OSC address ('/' then printable ASCII without spaces or "
                      f"'#', at most {MAX_ADDRESS} characters)")
            return
        if name == "IGNORE":
            self._ignore(client, [path])
        elif path not in client.listens:
            self._listen(client, path)

    def _listen(self, client: _Client, path: str) -> None:
        if len(client.listens) >= MAX_LISTENS:
            self._bad(f"LISTEN {path[:80]!r}: a client may listen to at most {MAX_LISTENS} paths")
            return
        if path not in self.live:  # kept: it streams once a robot serves it
            if len(client.unserved) >= MAX_UNSERVED:
                self._bad(f"LISTEN {path[:80]!r}: not served, and this client already listens to "
                          f"{MAX_UNSERVED} paths that were not")
                return
            self.adapter.warn("listen", f"LISTEN {path[:80]!r}: no such node (yet); its values come when it is "
                                        "served")
            client.unserved.add(path)
        else:
            path = sys.intern(path)  # (one string per served path, however many clients listen)
        client.listens.add(path)
        self.listened[path] = self.listened.get(path, 0) + 1

    def _ignore(self, client: _Client, paths: Iterable[str]) -> None:
        for path in paths:
            if path in client.listens:
                client.listens.discard(path)
                client.unserved.discard(path)
                left = self.listened.get(path, 1) - 1
                if left:
                    self.listened[path] = left
                else:
                    self.listened.pop(path, None)

    def _bad(self, what: str) -> None:
        self.adapter.count("bad")
        self.adapter.warn("ws", f"WebSocket: refused {what}")

    def _send_osc(self, messages: list[tuple[str, bytes]]) -> None:
        """Each client's messages framed and handed to it at once (one write when it can)."""
        sent = 0
        for client in self._clients:
            parts: list[bytes] = []
            listens = client.listens
            for path, data in messages:
                if path in listens:
                    parts += (frame_header(BINARY, len(data)), data)
            if parts:
                client.put_frames(parts, 2)
                sent += len(parts) // 2
        if sent:
            self.adapter.count("sent", sent)

    def _push_all(self, text: str) -> None:
        for client in self._clients:
            client.push(text)

    async def _close_all(self, app: web.Application) -> None:
        await close_clients(self._clients)


class _Client(FramedClient):
    """A WebSocket client and the paths it listens to (``LISTEN``); what it is due is written
    as whole frames, several in one write (``FramedClient``)."""

    def __init__(self, ws: web.WebSocketResponse, request: web.Request, adapter: Adapter) -> None:
        super().__init__(ws, lambda: adapter.count("ws_dropped"), request)
        self.listens: set[str] = set()
        self.unserved: set[str] = set()  # those not served when LISTENed (at most MAX_UNSERVED)
