"""The routes of the web pages and their WebSocket clients, on ``bus/web.py``'s ``WebServer``.

``/`` and ``/ws`` are the operator's, ``/kiosk`` and ``/kiosk/ws`` the kiosk's (``auth.Guard``
checks each request), ``/static/<file>`` the shipped pages' code and ``/kiosk/image/<id>``
a kiosk button's image. What clients send is read by ``protocol.parse``; commands are
shaped by ``commands.from_json`` and sent with ``client.ask``; every answer comes back
as a ``reply``. The adapter hands the bus's news to ``robots``, ``frames``, ``stats``,
``event`` and ``robot_left`` from any thread (they run on the server's loop).
"""

from __future__ import annotations

import asyncio
import functools
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aiohttp import WSMessage, WSMsgType, web

from sonibus.bus import client as bus_client
from sonibus.bus import commands
from sonibus.bus.errors import CommandError
from sonibus.bus.text import printable
from sonibus.bus.web import WebClient, WebServer, close_clients

from . import activity, kiosk, maps, protocol
from .auth import Guard
from .config import Button, WebConfig
from .kiosk import Stand
from .slider import Coalescer

if TYPE_CHECKING:
    from sonibus.bus.adapter import Adapter

STATIC = Path(__file__).resolve().parent / "static"
MAX_WS_MESSAGE = 1 << 20  # bytes; aiohttp closes a connection that sends more in one message (code 1009)
HEARTBEAT_S = 10.0        # a ping this often; a client that does not answer within half of it is dropped
_FILE = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]{0,99}")
HEADERS = {"Cache-Control": "no-store", "Referrer-Policy": "no-referrer", "X-Frame-Options": "DENY",
           "X-Content-Type-Options": "nosniff"}  # (the token is in the page's URL: never sent on, never cached)
_dumps = functools.partial(json.dumps, allow_nan=False)
MAX_ASKING = 256           # commands of one page waiting for their robots' answers; past this: "dropped"
MAX_ANSWERS_WAITING = 1024  # answers waiting for a page to read them; past this its requests are not read
ROOM_POLL_S = 0.02


class Client(WebClient):
    """A page's WebSocket: ``role`` "operator" or "kiosk". Every request it sends is
    answered (``answer``: kept, never dropped, ahead of frames and stats); ``asking``
    counts its commands waiting for a robot's answer."""

    def __init__(self, ws: web.WebSocketResponse, role: str, adapter: Adapter,
                 transport: asyncio.BaseTransport | None) -> None:
        super().__init__(ws, lambda: adapter.count("dropped"), transport)
        self.role = role
        self.asking = 0

    def send(self, message: dict[str, Any]) -> None:
        self.push(_dumps(message))

    def answer(self, message: dict[str, Any]) -> None:
        """A ``reply`` (or a kiosk button's state): never dropped, sent before what the bus says."""
        self.push(_dumps(message), kept=True)

    async def room(self) -> None:
        """Return once fewer than ``MAX_ANSWERS_WAITING`` answers wait to be sent: a page that
        does not read what it asked for is not read either (its requests wait in TCP)."""
        while len(self.kept) >= MAX_ANSWERS_WAITING and not self.ws.closed:
            await asyncio.sleep(ROOM_POLL_S)


class Pages:
    """The pages' routes on ``web`` (a ``WebServer`` not started yet) for ``adapter``."""

    def __init__(self, adapter: Adapter, web_server: WebServer, config: WebConfig,
                 images: dict[str, str] | None = None) -> None:
        self.adapter, self.web, self.config = adapter, web_server, config
        self.images = images or {}  # kiosk button id → its image file (resolved by the node)
        self.guard = Guard(config.token, config.kiosk_token, adapter.name, adapter.count)
        self.operators: set[Client] = set()
        self.kiosks: set[Client] = set()
        self.stand = Stand(config.stand, self._to_kiosks)
        self.sliders: Coalescer  # made when the server starts (it runs on its loop's clock)
        self._robots: str | None = None   # the latest robots message, for a page that connects
        self._stats: str | None = None
        self._maps: str | None = None     # the latest maps message (the mappings panel: maps.py)
        self.on_operator: list[Callable[[], None]] = []  # each told (on the loop) when an operator's page comes
        app = web_server.app
        app.router.add_get("/", functools.partial(self._page, "operator"))
        app.router.add_get("/kiosk", functools.partial(self._page, "kiosk"))
        app.router.add_get("/ws", functools.partial(self._websocket, "operator"))
        app.router.add_get("/kiosk/ws", functools.partial(self._websocket, "kiosk"))
        app.router.add_get("/static/{name}", self._static)
        app.router.add_get("/kiosk/image/{id}", self._image)
        app.on_startup.append(self._startup)
        app.on_shutdown.append(self._close_all)

    # -- from any thread -------------------------------------------------------------

    def robots(self, robots: dict[str, Any]) -> None:
        self.web.call(self._set_robots, _dumps({"type": "robots", "robots": robots}))

    def stats(self, nodes: list[dict[str, Any]]) -> None:
        self.web.call(self._set_stats, _dumps({"type": "stats", "nodes": nodes}))

    def maps(self, text: str) -> None:
        """The map nodes' maps (a ``maps`` message), kept for a page that connects."""
        self.web.call(self._set_maps, text)

    def to_operators(self, text: str) -> None:
        self.web.call(self._to_operators, [text])

    def event(self, robot: str, kind: str, event: dict[str, Any], shown: bool) -> None:
        """``robot``'s event (``shown``: to the operator's pages too)."""
        text = _dumps({"type": "event", "robot": robot, "kind": kind, "event": event}) if shown else ""
        self.web.call(self._event, robot, kind, event, text)

    def robot_left(self, robot: str) -> None:
        self.web.call(self.stand.robot_left, robot)

    # -- routes (on the loop) --------------------------------------------------------

    async def _page(self, role: str, request: web.Request) -> web.StreamResponse:
        self.guard.check(request, role)
        return web.FileResponse(STATIC / f"{role}.html", headers=HEADERS)

    async def _static(self, request: web.Request) -> web.StreamResponse:
        self.guard.check(request, "asset")
        name = request.match_info["name"]
        path = STATIC / name
        if not _FILE.fullmatch(name) or not path.is_file():
            raise web.HTTPNotFound(text=f"no file {name[:100]!r} in the pages' static files\n")
        return web.FileResponse(path, headers=HEADERS)

    async def _image(self, request: web.Request) -> web.StreamResponse:
        self.guard.check(request, "asset")
        image = self.images.get(request.match_info["id"])
        if image is None:
            raise web.HTTPNotFound(text="no such kiosk button image\n")
        return web.FileResponse(image, headers=HEADERS)

    async def _websocket(self, role: str, request: web.Request) -> web.StreamResponse:
        self.guard.check(request, role)
        async with self.web.accept(request, max_msg_size=MAX_WS_MESSAGE, heartbeat=HEARTBEAT_S) as ws:
            client = Client(ws, role, self.adapter, request.transport)
            group = self.operators if role == "operator" else self.kiosks
            group.add(client)
            if role == "operator":
                for told in self.on_operator:
                    told()
            self.adapter.count("clients")
            self._greet(client)
            try:
                await self.web.serve_client(ws, client, functools.partial(self._receive, client), client.room)
            finally:
                group.discard(client)
        return ws

    def _receive(self, client: Client, message: WSMessage) -> None:
        if message.type == WSMsgType.TEXT:
            self._take(client, message.data)
        elif message.type == WSMsgType.BINARY:
            self._bad(client, None, f"a binary message of {len(message.data)} bytes (the pages send JSON text)")

    def _greet(self, client: Client) -> None:
        cfg = self.config
        buttons = [_button(b) for b in cfg.stand.buttons] if client.role == "kiosk" else []
        client.send({"type": "hello", "role": client.role, "update_hz": cfg.update_hz, "slider_hz": cfg.slider_hz,
                     "speed": cfg.speed, "buttons": buttons})
        if client.role == "kiosk":
            for state in [*self.stand.states.values(), *([self.stand.show] if self.stand.show else [])]:
                client.send(state)
            return
        for text in (self._robots, self._stats, self._maps):
            if text is not None:
                client.push(text)

    # -- what clients send -----------------------------------------------------------

    def _take(self, client: Client, text: str) -> None:
        try:
            request = protocol.parse(text)
        except protocol.BadMessage as exc:
            self._bad(client, exc.id, str(exc))
            return
        if client.role == "kiosk":
            if not isinstance(request, protocol.Press):
                self._bad(client, request.id, f"a kiosk sends only press, not {type(request).__name__.lower()}")
            else:
                self._press(client, request)
        elif isinstance(request, protocol.Press):
            self._bad(client, request.id, "press is the kiosk's (/kiosk/ws); the operator sends command")
        elif isinstance(request, protocol.Stop):
            self._stop(client, request.id)
        elif isinstance(request, protocol.MapRequest):
            if self._room(client, request.id):
                maps.forward(self.adapter, self, client, request, self.config.timeout)
        else:
            self._command(client, request)

    def _bad(self, client: Client, id_: protocol.Id, what: str) -> None:
        self.adapter.count("bad")
        self.adapter.warn("ws", f"WebSocket ({client.role}): refused {printable(what)}")
        client.answer(protocol.reply(id_, what))

    def _command(self, client: Client, request: protocol.Command) -> None:
        try:
            args = commands.from_json(request.verb, request.args)
        except CommandError as exc:
            client.answer(protocol.reply(request.id, exc))
            return
        shown = self.adapter.shown_robots().get(request.robot)
        why = activity.refusal(shown["activity"], request.robot, request.verb) if shown else None
        if why is not None:  # (its show closed and put it to rest: a gesture would be reported, not made)
            self.adapter.count("refused")
            client.answer(protocol.reply(request.id, f"{request.verb}: {why}"))
            return
        if not self._room(client, request.id):
            return
        item = (client, request.id, request.robot, request.verb, args)
        if request.verb != "joints/set":
            self._ask(*item)
            return
        args.setdefault("speed", self.config.speed)
        superseded = self.sliders.offer((request.robot, tuple(args.get("names", ()))), item)
        if superseded is not None:
            self.adapter.count("commands_coalesced")
            superseded[0].answer(protocol.reply(superseded[1], {"coalesced": True}))

    def _room(self, client: Client, id_: protocol.Id) -> bool:
        """Whether ``client`` may have one more request waiting for an answer; if not, it is told."""
        if client.asking < MAX_ASKING:
            return True
        self.adapter.count("commands_dropped")  # (said, never silently lost: the page may send it again)
        client.answer(protocol.reply(id_, f"dropped: too many at once — {client.asking} commands of this page wait "
                                          f"for their robots' answers (at most {MAX_ASKING}); send it again once "
                                          "some are answered"))
        return False

    def _stop(self, client: Client, id_: protocol.Id) -> None:
        """Stop every robot of the bus at once (``client.stop_all``: one query, never queued
        behind anything); one reply per robot that answered, then one naming those on the bus
        that did not."""
        for held in self.sliders.cancel():
            held[0].answer(protocol.reply(held[1], "cancelled: a stop came first"))
        self.adapter.count("commands")

        answered: list[str] = []

        def done(robot: str, outcome: bus_client.Outcome) -> None:
            answered.append(robot)
            self.web.call(client.answer, protocol.reply(id_, outcome, robot))

        def silent(robots: list[str], error: CommandError) -> None:
            if robots:
                self.web.call(client.answer, protocol.silent(id_, robots, error))
            elif not answered:
                self.web.call(client.answer, protocol.reply(id_, "stop: no robot on the bus"))
        bus_client.stop_all(self.adapter.bus, done, silent, self.config.timeout)

    def _ask(self, client: Client, id_: protocol.Id, robot: str, verb: str, args: dict[str, Any]) -> None:
        self.adapter.count("commands")
        client.asking += 1

        def answered(outcome: bus_client.Outcome) -> None:
            client.asking -= 1
            client.answer(protocol.reply(id_, outcome))
        bus_client.ask(self.adapter.bus, robot, verb, args, lambda outcome: self.web.call(answered, outcome),
                       self.config.timeout)

    def _press(self, client: Client, request: protocol.Press) -> None:
        button = self.config.button(request.button)
        if button is None:
            known = ", ".join(b.id for b in self.config.stand.buttons) or "none"
            self._bad(client, request.id, f"press: no button {request.button[:64]!r} — buttons: {known}")
            return
        busy = self.stand.busy() or self.stand.closed()
        if busy:
            client.answer(protocol.reply(request.id, busy))
            return
        press = self.stand.press(button)
        asyncio.get_running_loop().call_later(button.timeout_s, self._overdue, press)
        self.adapter.count("commands")

        def done(outcome: bus_client.Outcome) -> None:
            self.web.call(self._pressed, client, request.id, button, press, outcome)
        kiosk.send(self.adapter.bus, self.config.stand.robot, button, done, self.config.timeout)

    def _overdue(self, press: int) -> None:
        button = self.stand.current
        if self.stand.overdue(press) and button is not None:
            self.adapter.count("buttons_timed_out")
            self.adapter.warn("kiosk", f"kiosk button {button.id!r}: no end heard from '{self.config.stand.robot}' "
                                       f"within {button.timeout_s:g} s — the kiosk takes presses again")

    def _pressed(self, client: Client, id_: protocol.Id, button: Button, press: int,
                 outcome: bus_client.Outcome) -> None:
        client.answer(protocol.reply(id_, outcome))
        self.stand.answered(button, outcome, press)

    # -- what the bus says (on the loop) ---------------------------------------------

    def push_frames(self, texts: list[str]) -> None:
        """Robots' ``frame`` messages to the operators' pages (the node's tick, on the loop)."""
        self._to_operators(texts)

    def _set_robots(self, text: str) -> None:
        self._robots = text
        self._to_operators([text])

    def _set_maps(self, text: str) -> None:
        self._maps = text
        self._to_operators([text])

    def _set_stats(self, text: str) -> None:
        self._stats = text
        self._to_operators([text])

    def _event(self, robot: str, kind: str, event: dict[str, Any], text: str) -> None:
        if text:
            self._to_operators([text])
        self.stand.event(robot, kind, event)

    def _to_operators(self, texts: list[str]) -> None:
        for client in self.operators:
            for text in texts:
                client.push(text)

    def _to_kiosks(self, message: dict[str, Any]) -> None:
        for client in self.kiosks:
            client.send(message)

    async def _startup(self, app: web.Application) -> None:
        self.sliders = Coalescer(asyncio.get_running_loop(), 1.0 / self.config.slider_hz, lambda i: self._ask(*i))

    async def _close_all(self, app: web.Application) -> None:
        await close_clients(self.operators | self.kiosks)


def _button(button: Button) -> dict[str, Any]:
    shown = {"id": button.id, "label": button.label, "kind": button.kind}
    if button.image:
        shown["image"] = f"/kiosk/image/{button.id}"
    return shown
