"""``Bus``: one node's handle on a Zenoh session, the only way adapters and the
core talk (``tests/test_bus_only.py`` fails if another module touches a session).

>>> from contextlib import closing
>>> from sonibus.bus import BusConfig, open_session
>>> with closing(open_session(BusConfig(multicast=False))) as session:
...     bus = Bus(session, node="demo")
...     bus.put("pepper/events/hello", {"t": 0.0, "kind": "hello"})
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, NamedTuple, TypeVar

import zenoh
import zenoh.ext

from . import codec, keys
from .control import URGENT
from .fanout import Fanout
from .messages import Limits
from .queue import SampleQueue
from .session import discover, lease_s, listening

T = TypeVar("T")
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Qos:
    """How a publisher's samples travel: Zenoh's reliability, priority, congestion
    control (drop under congestion, or block the publisher) and express (no batching)."""

    reliable: bool = True
    priority: str = "DATA"  # a zenoh.Priority by name: REAL_TIME, INTERACTIVE_HIGH, ..., DATA_HIGH, DATA, ...
    drop: bool = False
    express: bool = False

    def options(self, publisher: bool = True) -> dict[str, Any]:
        """Keyword arguments of Zenoh's ``declare_publisher`` (``put``: no reliability, a publisher's)."""
        options = {"priority": getattr(zenoh.Priority, self.priority), "express": self.express,
                   "congestion_control": zenoh.CongestionControl.DROP if self.drop else zenoh.CongestionControl.BLOCK}
        if publisher:
            options["reliability"] = zenoh.Reliability.RELIABLE if self.reliable else zenoh.Reliability.BEST_EFFORT
        return options


# High-rate data (joint samples, frames): drops under congestion, never back-pressures. Not
# express: batching measured lossless where express lost samples on a busy 2-core machine,
# at no cost in latency (docs/performance.md).
STREAM = Qos(priority="DATA_HIGH", drop=True)
# Audio chunks (bus/audio.py): a late chunk is worth no more than a lost one (the jitter buffer
# plays silence for either), so never back-pressure the publisher (a JACK callback). Express: no
# batching wait; at 50-100 chunks/s it measured neither slower nor lossy (docs/design.md, "Audio").
AUDIO = Qos(priority="DATA_HIGH", drop=True, express=True)
EVENTS = Qos()  # low rate, must not be dropped: blocks rather than drop


class Reply(NamedTuple):
    """One answer to ``Bus.ask``: its key and payload, or the ``error`` Zenoh reported."""

    key: str
    payload: bytes | None
    error: str = ""


class Entities(NamedTuple):
    """Zenoh entities declared together (a watch, a robot's publishers); ``undeclare`` ends them all."""

    entities: tuple[Any, ...]

    def undeclare(self) -> None:
        errors = []
        for entity in self.entities:  # each, whatever the others do
            try:
                entity.undeclare()
            except Exception as exc:  # a session closed underneath
                errors.append(exc)
        if errors:
            raise errors[0]


class Bus:
    """Publish, subscribe, serve and ask on the bus, as node ``node`` of ``host``."""

    def __init__(self, session: zenoh.Session, node: str = "", host: str | None = None,
                 limits: Limits | None = None, control: zenoh.Session | None = None) -> None:
        self.session = session  # for tests and the few tools that open one; nodes use the methods
        # the process's control session (``bus/control.py``): stop served and sent on a link of its own
        self.control = control
        self.node = node
        self.host = host or socket.gethostname()
        self.limits = limits or Limits()  # what the gate of each node on this bus lets through
        self._shared: dict[str, Any] = {}  # per session, for every node's Bus on it (see ``shared``)
        self._lock = threading.Lock()
        # the session's subscriptions, one Zenoh subscriber per key expression (``bus/fanout.py``), shared
        # by every node's Bus like ``_shared`` (not in it: a view made by ``shared`` may subscribe)
        self._subscriptions = Fanout(lambda keyexpr, callback: session.declare_subscriber(keyexpr, callback))
        # what a callback of this node that raised is handed to (its adapter's ``fail``): Zenoh would
        # print it and go on, and the node would report itself well while hearing nothing
        self.on_error: Callable[[str, BaseException], None] | None = None

    def for_node(self, node: str) -> Bus:
        bus = Bus(self.session, node, self.host, self.limits, self.control)
        bus._shared, bus._lock, bus._subscriptions = self._shared, self._lock, self._subscriptions
        return bus

    def guarded(self, callback: Callable[..., Any], what: str) -> Callable[..., Any]:
        """``callback`` as Zenoh will call it: an exception goes to ``on_error`` (if set)."""
        def run(*args: Any) -> Any:
            try:
                return callback(*args)
            except Exception as exc:
                if self.on_error is None:
                    raise
                self.on_error(what, exc)
                return None
        return run

    def shared(self, name: str, make: Callable[[Bus], T]) -> T:
        """The one ``make(self)`` of this session (a view every node on it shares), made on first use."""
        with self._lock:
            if name not in self._shared:
                self._shared[name] = make(self)
            return self._shared[name]

    # -- publishing -------------------------------------------------------------------

    def stream_publisher(self, key: str, qos: Qos = STREAM, encoding: str | None = codec.ENCODING,
                         cache: int = 0) -> Any:
        """A publisher of msgpack payloads on ``key`` (default: high-rate data, ``STREAM``).
        Another protocol's payloads (a ROS 2 message) take their ``encoding`` (None: Zenoh's
        default); ``cache`` > 0 keeps that many last samples for late subscribers that ask for
        history (zenoh-ext's advanced publisher: what rmw_zenoh does for transient local)."""
        options = {**qos.options(), **({"encoding": encoding} if encoding else {})}
        if cache:
            return zenoh.ext.declare_advanced_publisher(  # sequenced by number: no session timestamping needed
                self.session, key, cache=zenoh.ext.CacheConfig(max_samples=cache),
                sample_miss_detection=zenoh.ext.MissDetectionConfig(), publisher_detection=True, **options)
        return self.session.declare_publisher(key, **options)

    def put(self, key: str, message: dict[str, Any], qos: Qos = EVENTS) -> None:
        """Send one message (default: reliably, ``EVENTS``: events are few and must not be lost)."""
        self.session.put(key, codec.encode(message), encoding=codec.ENCODING, **qos.options(publisher=False))

    def watch_subscribers(self, keyexpr: str, changed: Callable[[bool], None]) -> Entities:
        """Call ``changed(True/False)`` now and whenever anyone starts or stops
        subscribing to ``keyexpr``; undeclare what it returns to stop."""
        interest = self.session.declare_publisher(keyexpr)
        listener = interest.declare_matching_listener(
            self.guarded(lambda status: changed(status.matching), f"listener of subscribers to {keyexpr}"))
        changed(interest.matching_status.matching)
        return Entities((listener, interest))

    # -- subscribing ------------------------------------------------------------------

    def subscribe(self, keyexpr: str, maxlen: int = 1024, queue: SampleQueue | None = None,
                  stamped: bool = False, skip: Callable[[str], bool] | None = None,
                  attachment: bool = False, history: bool = False, max_payload: int | None = None,
                  direct: Callable[[str, Any], bool] | None = None) -> tuple[Any, SampleQueue]:
        """Samples of ``keyexpr`` as ``(key, payload bytes)`` in a bounded queue
        (``(key, payload, time.monotonic_ns())`` of arrival if ``stamped``). A payload
        over the gate's size limit is queued as ``codec.Oversize`` (its size only).

        ``keyexpr`` may use globs inside a chunk (``pepper/joints/R*``); a bad one
        raises ``ConfigError``. Pass ``queue`` to feed several subscriptions into one,
        ``skip`` to leave out the keys it returns True for. For another protocol's
        traffic (ROS 2 over rmw_zenoh): ``attachment`` queues each sample's attachment
        (bytes, or None) after its payload, ``history`` asks publishers with a cache for
        what they hold, late joiners too (zenoh-ext's advanced subscriber), and
        ``max_payload`` replaces the gate's size limit. ``direct(key, payload)`` is called first,
        on the subscriber's thread, and what it returns True for is not queued (``Streams``' direct).

        The subscriptions of one session to the same key expression share one Zenoh
        subscriber and its thread (``bus/fanout.py``; not those with ``history``), and so do
        those a broader one includes that the session subscribes to or planned (``plan``),
        each given only its own keys: what this returns undeclares this subscription alone,
        the last one a Zenoh subscriber serves that subscriber."""
        keyexpr = keys.expr(keyexpr)
        queue = queue if queue is not None else SampleQueue(maxlen)

        def enqueue(key: str, payload: bytes | codec.Oversize, sample: zenoh.Sample) -> None:
            if skip is None or not skip(key):
                item: tuple[Any, ...] = (key, payload)
                if attachment:
                    item += (sample.attachment.to_bytes() if sample.attachment is not None else None,)
                queue.put((*item, time.monotonic_ns()) if stamped else item)

        # (``direct`` given to the fanout, which calls it, and ``enqueue`` for what it declines, itself:
        # no Python call between Zenoh's callback and the sink's but the fanout's; issue 35)
        if direct is not None and skip is not None:
            taken, skipped = direct, skip

            def direct(key: str, payload: bytes | codec.Oversize) -> Any:
                return not skipped(key) and taken(key, payload)  # (declined: ``enqueue`` leaves it out too)
        what = f"subscriber to {keyexpr}"
        fits = self._fits(max_payload)
        if history:  # (an advanced subscriber of its own: what it asks publishers for is its alone)
            def advanced(sample: zenoh.Sample) -> None:
                key, payload, sample = self._taken(sample, fits)
                if direct is None or not direct(key, payload):
                    enqueue(key, payload, sample)
            return zenoh.ext.declare_advanced_subscriber(
                self.session, keyexpr, self.guarded(advanced, what),
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True)), queue
        # (guarded by the fanout, in its own frame: ``_fails``)
        return self._subscriptions.join(keyexpr, enqueue, fits, self._whole(max_payload), self._fails(what),
                                        direct), queue

    def plan(self, keyexprs: Iterable[str]) -> None:
        """Say the key expressions this session's nodes will subscribe to (the runner, from each
        node's ``subscribe``, before any starts; ``ConfigError`` for a bad one): a node's
        subscription that a broader one of them includes is then served by that one's Zenoh
        subscriber, whichever node subscribes first (``bus/fanout.py``)."""
        self._subscriptions.plan(keys.expr(keyexpr) for keyexpr in keyexprs)  # (as ``subscribe`` writes them)

    def on_sample(self, keyexpr: str, take: Callable[[str, bytes | codec.Oversize], None], what: str) -> Any:
        """Call ``take(key, payload)`` on Zenoh's thread for each sample of ``keyexpr``, with no
        queue between (for what must act at once: a stop seen on a robot's events); ``take``
        must only store or signal. A payload over the gate's limit comes as ``codec.Oversize``."""
        return self._subscriptions.join(keys.expr(keyexpr), lambda key, payload, sample: take(key, payload),
                                        self._fits(None), self._whole(None), self._fails(what))

    def _fails(self, what: str) -> Callable[[Exception], None]:
        """What the fanout hands a subscription's exception to: ``on_error`` (read then), as ``guarded``."""
        def fail(exc: Exception) -> None:
            if self.on_error is None:
                raise exc
            self.on_error(what, exc)
        return fail

    def _whole(self, limit: int | None) -> int:
        """The size up to which ``_fits(limit)`` keeps any payload whole (the fanout asks it beyond)."""
        return limit if limit is not None else self.limits.max_payload

    def _fits(self, limit: int | None) -> Callable[[str, int], bool]:
        """Whether a payload of a size on a key is kept whole: at most ``limit`` bytes, or
        (``limit`` None) within the gate's limit of the key's section."""
        if limit is not None:
            return lambda key, size: size <= limit

        def within(key: str, size: int) -> bool:
            if size <= self.limits.max_payload:
                return True
            try:
                section = keys.Key.parse(key).section
            except ValueError:
                section = ""
            return size <= self.limits.payload_limit(section)
        return within

    @staticmethod
    def _taken(sample: zenoh.Sample, fits: Callable[[str, int], bool]) -> tuple[str, bytes | codec.Oversize, Any]:
        """``sample`` as a subscription takes it: its key, its payload (or only its size, past ``fits``)."""
        key, payload = str(sample.key_expr), sample.payload
        size = len(payload)
        return key, payload.to_bytes() if fits(key, size) else codec.Oversize(size), sample

    # -- presence (liveliness tokens) ---------------------------------------------------

    def token(self, key: str) -> zenoh.LivelinessToken:
        """Be seen under ``key`` for as long as the token is declared (and the link is up)."""
        return self.session.liveliness().declare_token(key)

    def alive(self, keyexpr: str, timeout: float = 1.0) -> list[str]:
        """Keys of the liveliness tokens alive under ``keyexpr`` (at most ``MAX_ALIVE``)."""
        found: list[str] = []
        done = threading.Event()

        def take(reply: zenoh.Reply) -> None:
            if reply.ok is not None and len(found) < MAX_ALIVE:
                found.append(str(reply.ok.key_expr))
        # Not the default channel of 256 replies: Zenoh hands over the tokens it knows inside
        # ``get`` itself, before anyone reads the channel, so a 257th token blocked it for ever
        # (a recorder asking with 1,200 made-up claims on the bus hung)
        self.session.liveliness().get(keyexpr, zenoh.handlers.Callback(take, done.set, indirect=False),
                                      timeout=timeout)
        done.wait(timeout + 1.0)
        return sorted(found)

    def watch_tokens(self, keyexpr: str, changed: Callable[[str, bool], None]) -> zenoh.Subscriber:
        """Call ``changed(key, alive)`` for every token under ``keyexpr`` alive now and
        whenever one appears or goes (on a Zenoh thread)."""
        return self.session.liveliness().declare_subscriber(
            keyexpr, self.guarded(lambda s: changed(str(s.key_expr), s.kind == zenoh.SampleKind.PUT),
                                  f"watcher of {keyexpr}"), history=True)

    def token_events(self, keyexpr: str, capacity: int) -> zenoh.Subscriber:
        """The changes of the liveliness tokens under ``keyexpr``, those alive now first, held
        in a ring channel of ``capacity`` inside Zenoh: ``recv()`` waits for the next (a
        ``zenoh.Sample``: ``key_expr``, ``kind``), ``try_recv()`` does not (None). Zenoh's
        threads never wait for Python here (a callback's channel of 256 blocks them when full):
        past ``capacity`` the oldest are dropped, so a reader that drains a full channel
        reads the tokens again (``alive``). Undeclare what it returns to stop."""
        return self.session.liveliness().declare_subscriber(keyexpr, zenoh.handlers.RingChannel(capacity),
                                                            history=True)

    @property
    def closed(self) -> bool:
        """Whether this bus's session has been closed."""
        return self.session.is_closed()

    @property
    def zid(self) -> str:
        """This session's Zenoh id (another protocol's graph names it: rmw_zenoh's liveliness tokens)."""
        return str(self.session.zid())

    def discover(self, served: str = "") -> list[str]:
        """Wait until this session is really on the bus (``session.discover``; with ``served``,
        until a queryable of that key is known, at most as long); the ids it reached."""
        return discover(self.session, served)

    @property
    def listening(self) -> tuple[str, ...]:
        """Where this session listens, each port as really bound (a listen on port 0 too)."""
        return listening(self.session)

    @property
    def lease_s(self) -> float:
        """How long a vanished peer's tokens last (the transport lease), in s."""
        return lease_s(self.session)

    # -- serving and asking -------------------------------------------------------------

    def serve(self, keyexpr: str, handler: Callable[[zenoh.Query], None]) -> zenoh.Queryable:
        return self.session.declare_queryable(keyexpr, self.guarded(handler, f"server of {keyexpr}"))

    def serve_urgent(self, keyexpr: str, handler: Callable[[zenoh.Query], None]) -> zenoh.Queryable | None:
        """Serve ``keyexpr`` on the control session (None without one), ``handler`` called on
        Zenoh's own thread: nothing of the data path (its links, its channels) in between."""
        if self.control is None:
            return None
        return self.control.declare_queryable(
            keyexpr, zenoh.handlers.Callback(self.guarded(handler, f"server of {keyexpr}"), indirect=False))

    def ask(self, selector: str, on_reply: Callable[[Reply], None], on_end: Callable[[], None], *,
            message: dict[str, Any] | None = None, timeout: float = 5.0, every_answer: bool = False,
            urgent: bool = False) -> None:
        """Send a query without waiting: each answer goes to ``on_reply`` and the end of
        the query (all answered, or ``timeout``) to ``on_end``, on Zenoh threads.
        ``every_answer``: no consolidation (several nodes may answer one key); ``urgent``
        (a stop): from the control session, if any, at Zenoh's real-time priority."""
        def reply(answer: zenoh.Reply) -> None:
            if answer.ok is not None:
                on_reply(Reply(str(answer.ok.key_expr), answer.ok.payload.to_bytes()))
            else:
                on_reply(Reply(selector, None, answer.err.payload.to_string()))

        options: dict[str, Any] = {"consolidation": zenoh.ConsolidationMode.NONE} if every_answer else {}
        session = self.session
        if urgent:
            options.update(URGENT)
            session = self.control or self.session
        if message is not None:
            options.update(payload=codec.encode(message), encoding=codec.ENCODING)
        answers = _answers()
        reply_, end = self.guarded(reply, f"answer to {selector}"), self.guarded(on_end, f"end of {selector}")
        # Not zenoh-python's default (indirect): it starts a Python thread for each query, and
        # a thousand made-up robots asked about at once started thousands (STOP waited seconds)
        session.get(selector, zenoh.handlers.Callback(lambda answer: answers.reply(reply_, answer),
                                                      lambda: answers.end(end), indirect=False),
                    timeout=timeout, **options)

    def query(self, selector: str, message: dict[str, Any] | None = None,
              timeout: float = 5.0) -> list[dict[str, Any]]:
        """Decoded replies to a query; an empty list when nobody serves ``selector``."""
        payload = codec.encode(message) if message is not None else None
        replies = self.session.get(selector, payload=payload, encoding=codec.ENCODING, timeout=timeout)
        out = []
        for reply in replies:
            if reply.ok is not None:
                out.append(codec.decode(reply.ok.payload))
            else:
                out.append({"ok": False, "error": {"code": "internal",
                                                   "message": reply.err.payload.to_string()}})
        return out

    def __repr__(self) -> str:
        return f"<Bus node={self.node!r} host={self.host!r} zid={self.session.zid()}>"


MAX_ALIVE = 65536  # tokens ``Bus.alive`` returns
MAX_ANSWERS = 65536  # answers to ``ask`` waiting for the worker; past that, answers (never ends) are dropped


class _Answers:
    """One worker of the process that runs what ``Bus.ask`` was told to call, in the order
    Zenoh hands it over: Zenoh's thread only enqueues (it must not decode a 1 MiB info), and
    no thread is started per query. Answers past ``MAX_ANSWERS`` (a rogue queryable may answer
    a query many times) are dropped and said; a query's end never is (its asker waits for it)."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[tuple[Callable[..., Any], tuple[Any, ...]]] = queue.SimpleQueue()
        self.dropped = 0
        self._said = -1e18
        threading.Thread(target=self._run, name="answers", daemon=True).start()

    def reply(self, take: Callable[[zenoh.Reply], Any], answer: zenoh.Reply) -> None:
        if self._queue.qsize() >= MAX_ANSWERS:
            self.dropped += 1
            if time.monotonic() - self._said >= 10.0:
                self._said = time.monotonic()
                log.warning("answers to queries: more than %d waiting, %d dropped so far (a queryable that "
                            "answers far more than asked?)", MAX_ANSWERS, self.dropped)
            return
        self._queue.put((take, (answer,)))

    def end(self, end: Callable[[], Any]) -> None:
        self._queue.put((end, ()))

    def _run(self) -> None:
        while True:
            call, args = self._queue.get()
            try:
                call(*args)
            except Exception:  # (a node's callback with no on_error): said, and the next one runs
                log.exception("an answer to a query failed")


_ANSWERS: list[_Answers] = []
_ANSWERS_LOCK = threading.Lock()


def _answers() -> _Answers:
    with _ANSWERS_LOCK:
        if not _ANSWERS:
            _ANSWERS.append(_Answers())
        return _ANSWERS[0]
