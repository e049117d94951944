"""The channels the ``foxglove`` adapter serves and the clients that read them, on
``bus/web.py``'s ``WebServer`` (so within its limits, timeouts and browser check).

A channel exists before it is advertised: ``log`` makes it under the lock, then the
advertisement goes out on the server's loop, so a client that subscribes as soon as it
hears of a channel always finds it. Each channel keeps its latest message (as logged,
not yet JSON) and a subscription gets it first, as a latched topic: the first message of
a channel made while a client is connected (a robot's first event, ``<robot>/log``) is
not lost to the client's subscribing a moment later. A message is made JSON only for
channels someone subscribes to.

A channel of events (``<robot>/log``, ``<robot>/events/<kind>``: ``history=True``) keeps
more than its latest: a subscription gets every message the channel logged since it was
advertised to that client, in order, then the live ones (issue 33: a viewer subscribes a
moment after it hears of a channel, and a behavior's ``started`` and ``ok`` can both come
in that moment; the latest alone showed ``[ok, stopped]`` where the run was ``[started,
ok, ...]``). A client that connects later gets the latest, as before. What is kept is
bounded: ``HISTORY`` messages a channel, ``HISTORY_BYTES`` of JSON for all channels
(past that a channel keeps only its latest; a flood of made-up event keys cannot grow it).

``forget`` unadvertises the channels of a robot that left (and their latest messages go):
a viewer drops those topics, and subscribes again when they are advertised anew (new ids)
as the robot comes back. A subscription to a channel unadvertised since is kept, inert,
until the client unsubscribes it, as Lichtblick does on ``unadvertise``: that unsubscribe
is no error.

What goes to the clients (advertisements, messages, unadvertisements) is handed to the
server's loop in batches, in order: ``log`` adds to the hub's outbox, and the loop is
asked to empty it only if it was empty (a call into the loop is a wake-up and a write
to its pipe: one per message, 2,300 a second with a robot and its derived values,
took 14 % of the node's CPU).
"""

from __future__ import annotations

import contextlib
import json
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from threading import Lock
from typing import TYPE_CHECKING, Any

from aiohttp import WSMessage, WSMsgType, web

from sonibus.bus.web import WebServer, close_clients

from . import wire
from .framed import FramedClient

if TYPE_CHECKING:
    from sonibus.bus.adapter import Adapter

MAX_CHANNELS = 4096         # channels advertised at most (keys made up on the fly must not grow it for ever)
MAX_SUBSCRIPTIONS = MAX_CHANNELS  # one client's, inert ones (their channel gone) included
MAX_WS_MESSAGE = 1 << 20    # bytes of one client message; aiohttp closes a connection that sends more (1009)
MAX_OUTBOX = 8192           # messages waiting for the server's loop; past it a message is dropped (a stuck loop)
HEARTBEAT_S = 10.0          # a ping this often; a client that does not answer within half of it is dropped
HISTORY = 256               # messages an event channel keeps for a subscription taken a moment after advertising
HISTORY_BYTES = 16 << 20    # bytes of JSON all event channels keep together (past it: the latest only)


@dataclass
class _Channel:
    described: wire.Channel
    latest: tuple[Any, int] | None = None            # (message, log time ns), as logged
    subscribers: dict[_Client, int] = field(default_factory=dict)  # client → its subscription id
    logged: int = 0                                  # messages logged on it (the number of the latest)
    history: deque[tuple[int, int, bytes]] | None = None  # event channels: (number, log time ns, JSON)
    history_bytes: int = 0


class _Client(FramedClient):
    """A client and its subscriptions (subscription id → channel id); what it is due waits as
    frames in parts (``FramedClient``): a message's parts are shared by every client, only its
    4-byte subscription id is the client's own."""

    def __init__(self, ws: web.WebSocketResponse, on_drop: Callable[[], None], request: web.Request,
                 on_write: Callable[[], None]) -> None:
        super().__init__(ws, on_drop, request, on_write)
        self.subscriptions: dict[int, int] = {}
        self.advertised: set[int] = set()  # channel ids told to it (an advertisement never goes twice)
        self.since: dict[int, int] = {}    # channel id → the number of its first message since it was told of it
                                           # (until its first subscription; on the loop)


class Hub:
    """Channels by topic, served to Foxglove clients on ``web`` (routes added here; the
    adapter starts the server); ``to_json`` turns a logged message into the payload;
    ``metadata`` goes in ``serverInfo``."""

    def __init__(self, adapter: Adapter, web_server: WebServer, name: str, to_json: Callable[[Any], bytes],
                 metadata: dict[str, str] | None = None) -> None:
        self.adapter, self.web, self.name, self.to_json = adapter, web_server, name, to_json
        self.metadata = metadata or {}  # serverInfo's (never ROS_DISTRO: a viewer would load ROS's types)
        self.session = str(time.time_ns())  # (a viewer that reconnects to a new session starts afresh)
        self._channels: dict[str, _Channel] = {}
        self._by_id: dict[int, _Channel] = {}
        self._clients: set[_Client] = set()
        self._last_id = 0  # channel ids are never given twice (a viewer caches a channel's schema by its id)
        self._history_bytes = 0  # what every event channel's history holds (under _lock)
        self._lock = Lock()  # channels, latest messages, subscribers: the adapter's thread and the loop
        self._outbox: list[tuple[Callable[..., None], tuple[Any, ...]]] = []  # for the loop, in order (under _lock)
        self._waiting = 0  # messages in the outbox's batches (under _lock)
        self._batching = False  # the loop serves messages and flushes after them (batch): no call to it (under _lock)
        web_server.app.router.add_get("/{path:.*}", self._websocket)  # (a client may name any path)
        web_server.app.on_shutdown.append(lambda app: close_clients(list(self._clients)))

    @property
    def channels(self) -> int:
        return len(self._channels)

    @property
    def clients(self) -> int:
        return len(self._clients)

    def log(self, topic: str, message: Any, log_time_ns: int, describe: Callable[[int], wire.Channel],
            history: bool = False) -> bool:
        """``message`` on the channel of ``topic`` (made, by ``describe(id)``, and advertised if
        new), to its subscribers; False if the channel cannot be made (``MAX_CHANNELS``).
        ``history``: a channel of events, whose messages since a client was told of it reach
        its subscription (see the module's docstring). From any thread; what ``to_json``
        raises (not strict JSON) reaches the caller."""
        for _, problem in self.log_all([(topic, message)], log_time_ns, lambda id_, _: describe(id_), history):
            if isinstance(problem, Exception):
                raise problem
            return False
        return True

    def log_all(self, items: list[tuple[str, Any]], log_time_ns: int, describe: Callable[[int, str], wire.Channel],
                history: bool = False) -> list[tuple[str, Exception | None]]:
        """Each ``(topic, message)`` as ``log`` logs it (``history`` for all of them), in order,
        all at ``log_time_ns`` (what one message from the bus gives: a frame's joints, its
        views), with one hold of the lock and one batch for the server's loop (issue 35: what
        was paid per message, once). What could not be logged, with why: ``(topic, None)``
        for a channel that cannot be made (``MAX_CHANNELS``), ``(topic, exception)`` for what
        ``to_json`` raised."""
        problems: list[tuple[str, Exception | None]] = []
        encoded: list[bytes] = []  # (events: a few a second) their JSON first, for their history
        if history:
            kept = []
            for topic, message in items:
                try:
                    encoded.append(self.to_json(message))
                    kept.append((topic, message))
                except (ValueError, TypeError) as exc:
                    problems.append((topic, exc))
            items = kept
        due: list[tuple[list[tuple[_Client, int]], str, Any, bytes | None]] = []
        with self._lock:
            for i, (topic, message) in enumerate(items):
                payload = encoded[i] if history else None
                channel = self._channels.get(topic)
                if channel is None:
                    if len(self._channels) >= MAX_CHANNELS:
                        problems.append((topic, None))
                        continue
                    self._last_id += 1
                    channel = _Channel(describe(self._last_id, topic), history=deque() if history else None)
                    self._channels[topic] = self._by_id[channel.described.id] = channel
                    self._later(self._advertise, channel.described)
                channel.latest = (message, log_time_ns)
                channel.logged += 1
                if payload is not None and channel.history is not None:
                    self._keep(channel, (channel.logged, log_time_ns, payload))
                if channel.subscribers:
                    due.append((list(channel.subscribers.items()), topic, message, payload))
        sends: list[tuple[list[tuple[_Client, int]], bytes]] = []
        for subscribers, topic, message, payload in due:
            try:
                sends.append((subscribers, self.to_json(message) if payload is None else payload))
            except (ValueError, TypeError) as exc:
                problems.append((topic, exc))
        if sends:
            count = sum(len(subscribers) for subscribers, _ in sends)
            with self._lock:
                room = self._waiting + len(sends) <= MAX_OUTBOX
                if room:
                    self._waiting += len(sends)
                    self._later(self._send, sends, log_time_ns)
            self.adapter.count("sent" if room else "dropped_for_clients", count)
        return problems

    def _keep(self, channel: _Channel, entry: tuple[int, int, bytes]) -> None:
        """``entry`` in ``channel``'s history, within ``HISTORY`` and ``HISTORY_BYTES`` (under ``_lock``)."""
        history, size = channel.history, len(entry[2])
        while history and (len(history) >= HISTORY or self._history_bytes + size > HISTORY_BYTES):
            self._forget_oldest(channel)
        if self._history_bytes + size <= HISTORY_BYTES:
            history.append(entry)
            channel.history_bytes += size
            self._history_bytes += size

    def _forget_oldest(self, channel: _Channel) -> None:
        size = len(channel.history.popleft()[2])
        channel.history_bytes -= size
        self._history_bytes -= size

    def forget(self, prefix: str) -> int:
        """Unadvertise every channel whose topic starts with ``prefix`` (``"pepper/"``: a robot
        gone), its latest message with it; how many. From any thread."""
        with self._lock:
            gone = [c for topic, c in self._channels.items() if topic.startswith(prefix)]
            for channel in gone:
                del self._channels[channel.described.topic], self._by_id[channel.described.id]
                self._history_bytes -= channel.history_bytes
            if gone:
                self._later(self._unadvertise, {c.described.id for c in gone})
        return len(gone)

    def _later(self, function: Callable[..., None], *args: Any) -> None:
        """``function(*args)`` on the server's loop, after what is in the outbox (under ``_lock``)."""
        self._outbox.append((function, args))
        if len(self._outbox) == 1 and not self._batching and not self.web.call(self._flush):
            self._outbox.clear()  # (the server is not running: nobody to tell)
            self._waiting = 0

    @contextlib.contextmanager
    def batch(self) -> Iterator[None]:
        """On the server's loop: what is logged in the block is flushed at its end, by this
        call, not by a call to the loop (a write to its pipe, a wake-up of itself)."""
        with self._lock:
            self._batching = True
        try:
            yield
        finally:
            with self._lock:
                self._batching = False
            self._flush()

    def _flush(self) -> None:
        """What the outbox holds, in order; the messages of consecutive ``_send``s gathered per
        client and handed to it at once (``_Client.put_frames``: one write when it can)."""
        with self._lock:
            outbox, self._outbox, self._waiting = self._outbox, [], 0
        due: dict[_Client, list[bytes]] = {}  # client → its frames' parts, in order
        for function, args in outbox:
            if function == self._send:
                self._send(*args, due=due)
                continue
            self._hand(due)  # (what was gathered goes before an advertisement that follows it)
            function(*args)
        self._hand(due)

    @staticmethod
    def _hand(due: dict[_Client, list[bytes]]) -> None:
        for client, parts in due.items():
            client.put_frames(parts, 4)
        due.clear()

    # -- on the server's loop ------------------------------------------------------------

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        offered = [p.strip() for p in request.headers.get("Sec-WebSocket-Protocol", "").split(",")]
        if not set(offered) & set(wire.SUBPROTOCOLS):
            self._bad(f"a connection from {request.remote} offering {offered[:4] if any(offered) else 'no'} "
                      f"WebSocket subprotocol refused (400): it must offer {' or '.join(wire.SUBPROTOCOLS)}")
            raise web.HTTPBadRequest(text=f"400: offer the WebSocket subprotocol {' or '.join(wire.SUBPROTOCOLS)} "
                                          "(Foxglove's WebSocket protocol)\n")
        async with self.web.accept(request, protocols=wire.SUBPROTOCOLS, max_msg_size=MAX_WS_MESSAGE,
                                   heartbeat=HEARTBEAT_S, compress=False) as ws:  # (frames written as they are)
            client = _Client(ws, lambda: self.adapter.count("dropped_for_clients"), request,
                             lambda: self.adapter.count("writes"))
            client.push(json.dumps(wire.server_info(self.name, self.session, self.metadata)))
            with self._lock:
                known = [c.described for c in self._channels.values()]
                client.since = {c.described.id: c.logged + 1 for c in self._channels.values()}  # (from now on)
                self._clients.add(client)
            client.advertised.update(c.id for c in known)
            if known:
                client.push(json.dumps(wire.advertise(known)))
            self.adapter.count("clients")
            try:
                await self.web.serve_client(ws, client, lambda message: self._receive(client, message))
            finally:
                with self._lock:
                    self._clients.discard(client)
                    for channel_id in client.subscriptions.values():
                        if (channel := self._by_id.get(channel_id)) is not None:  # (None: unadvertised since)
                            channel.subscribers.pop(client, None)
        return ws

    def _advertise(self, channel: wire.Channel) -> None:
        text = json.dumps(wire.advertise([channel]))
        for client in list(self._clients):
            if channel.id not in client.advertised:
                client.advertised.add(channel.id)
                client.since[channel.id] = 1  # (made since it connected: every message it logged)
                client.push(text)

    def _unadvertise(self, ids: set[int]) -> None:
        for client in list(self._clients):
            told = sorted(ids & client.advertised)
            if told:  # (a viewer takes the unadvertising of a channel it was never told of for an error)
                client.advertised.difference_update(told)
                for channel_id in told:
                    client.since.pop(channel_id, None)
                client.push(json.dumps(wire.unadvertise(told)))

    def _send(self, sends: list[tuple[list[tuple[_Client, int]], bytes]], log_time_ns: int, *,
              due: dict[_Client, list[bytes]]) -> None:
        """Each message's frame, for each of its subscribers, added to ``due`` (``_flush``'s) in
        parts shared by every client (``wire.data_head``), none copied until the client's write."""
        stamp, head_of, subscription_of = wire.stamp(log_time_ns), wire.data_head, wire.subscription
        for subscribers, payload in sends:
            head = head_of(len(payload))
            for client, subscription in subscribers:
                parts = due.get(client)
                if parts is None:
                    parts = due[client] = []
                parts += (head, subscription_of(subscription), stamp, payload)

    def _receive(self, client: _Client, message: WSMessage) -> None:
        if message.type == WSMsgType.BINARY:
            self._refuse(client, f"a binary message of {len(message.data)} bytes (client publishing is not served)")
            return
        if message.type != WSMsgType.TEXT:
            return
        try:
            op, items = wire.parse(message.data)
        except wire.Refused as exc:
            self._refuse(client, str(exc))
            return
        if op == "subscribe":
            for subscription, channel_id in items:
                self._subscribe(client, subscription, channel_id)
        else:
            for subscription in items:
                self._unsubscribe(client, subscription)

    def _unsubscribe(self, client: _Client, subscription: int) -> None:
        with self._lock:
            channel_id = client.subscriptions.pop(subscription, None)
            channel = self._by_id.get(channel_id) if channel_id is not None else None
            if channel is not None:
                channel.subscribers.pop(client, None)
        if channel_id is None:
            self._refuse(client, f"Unknown subscription ID: {subscription} (not subscribed, or unsubscribed "
                                 "already)", wire.WARNING)

    def _subscribe(self, client: _Client, subscription: int, channel_id: int) -> None:
        first: list[tuple[int, bytes | None, Any]] = []  # (log time ns, JSON or None, message) to send first
        with self._lock:
            channel = self._by_id.get(channel_id)
            if len(client.subscriptions) >= MAX_SUBSCRIPTIONS:
                client.subscriptions = {s: c for s, c in client.subscriptions.items() if c in self._by_id}
            if subscription in client.subscriptions:
                problem = f"Subscription ID was already used: {subscription}"
            elif channel is None and channel_id in client.advertised:
                problem = ""  # unadvertised a moment ago, which the client is about to hear: inert till unsubscribed
                client.subscriptions[subscription] = channel_id
            elif channel is None or channel_id not in client.advertised:
                problem = f"Unknown channel ID: {channel_id}"
            elif client in channel.subscribers:
                problem = f"Client is already subscribed to channel: {channel_id}"
            elif len(client.subscriptions) >= MAX_SUBSCRIPTIONS:
                problem = f"Too many subscriptions: {MAX_SUBSCRIPTIONS} already"
            else:
                problem = ""
                client.subscriptions[subscription] = channel_id
                channel.subscribers[client] = subscription
                first = self._first(channel, client.since.pop(channel_id, channel.logged))  # (again: the latest)
        if problem:
            self._refuse(client, problem)
            return
        for log_time_ns, payload, message in first:  # (before any live one: those are behind in the outbox)
            if payload is None:
                try:
                    payload = self.to_json(message)
                except (ValueError, TypeError):
                    continue  # (said by log's caller when it was logged)
            client.push(wire.message_data(subscription, log_time_ns, payload))
            self.adapter.count("sent")

    @staticmethod
    def _first(channel: _Channel, since: int) -> list[tuple[int, bytes | None, Any]]:
        """What a new subscription hears first (under ``_lock``): an event channel's messages
        numbered ``since`` on (every one since the client was told of the channel), else
        (or if none) the latest, as a latched topic."""
        if channel.history:
            kept = [(t, payload, None) for number, t, payload in channel.history if number >= since]
            if kept:
                return kept
        return [] if channel.latest is None else [(channel.latest[1], None, channel.latest[0])]

    def _refuse(self, client: _Client, problem: str, level: int = wire.ERROR) -> None:
        client.push(json.dumps(wire.status(problem, level)))
        self._bad(f"a client's message refused: {problem}")

    def _bad(self, what: str) -> None:
        self.adapter.count("bad")
        self.adapter.warn("client", f"Foxglove server: {what}")
