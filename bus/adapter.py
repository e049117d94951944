"""The adapter contract: a typed config, ``start(bus)``, ``stop()``.

A subclass sets ``Config`` (a dataclass) and overrides the ``_start`` and
``_stop`` hooks; the base class owns the invariants: state checks, the node's
liveliness token, worker threads joined and Zenoh entities undeclared on stop,
and a worker that dies is never silent — the node's state becomes "failed",
a ``node`` event says so on ``sonibus/events/node``, and ``sonibus run`` ends
with a non-zero exit (unless the worker was spawned with ``restart=True``).

Every node counts what it does (``count``; ``stats`` reads like a dict) and
publishes its health once a second on ``sonibus/stats/<host>/<node>``
(``bus/stats.py``; read with ``bus/health.py``).

>>> from dataclasses import dataclass
>>> class Hello(Adapter):
...     @dataclass(frozen=True)
...     class Config:
...         greeting: str = "hello"
...     def _start(self) -> None:
...         self.bus.put("hello/events/greeting", {"t": 0.0, "kind": self.config.greeting})
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from . import codec, keys
from .errors import SonibusError
from .installed import name_of
from .node import Bus, Qos
from .ownership import Ownership
from .queue import SampleQueue
from .stats import BASE, Counters, Report

log = logging.getLogger(__name__)

JOIN_TIMEOUT_S = 2.0
WARN_EVERY_S = 10.0  # at most one warning of a kind in this time
RESTART_AFTER_S = 1.0  # a restartable worker that failed runs again after this
STATS_EVERY_S = 1.0    # how often a node publishes its stats
STATS_QOS = Qos(priority="DATA_LOW", drop=True)  # never in the way of data; a lost second is only a gap
HANG_S = 20.0  # a worker that takes nothing from its waiting queue this long (or a stats worker this still) hangs


@dataclass(frozen=True)
class NoOptions:
    """Config of an adapter that takes no options."""


class Adapter:
    """Base class of every adapter (robot owners, sinks, processors)."""

    Config: ClassVar[type] = NoOptions
    counters: ClassVar[tuple[str, ...]] = ()  # counters of this kind of node beside stats.BASE, shown from zero

    def __init__(self, config: Any = None, *, name: str = "") -> None:
        self.config = config if config is not None else self.Config()
        if not isinstance(self.config, self.Config):
            raise TypeError(f"{type(self).__name__} takes a {self.Config.__name__}, "
                            f"got {type(self.config).__name__}")
        self.name = name or type(self).__name__.lower()
        self.kind = name_of(type(self))  # "sim", not "SimRobot", in logs, stats and `sonibus nodes`
        self.state = "new"
        self.stopping = threading.Event()
        self.robots: list[str] = []       # robots this node owns (see claim_robot)
        self.where: Callable[[str], str] | None = None  # key → "file [nodes.x] line N", when built from a file
        self.folder: Path | None = None   # the installation file's folder, when built from one (for relative paths)
        self.file: Path | None = None     # the installation file itself, when built from one (a map node saves into it)
        self.since = 0.0                  # when it started (epoch seconds)
        self.address = ""                 # where a person reaches it once started (a page's URL), said by `run`
        self.stats = Counters(BASE + self.counters)  # what it did (count() adds; dropped: its queues')
        self.failure = ""                 # why the node failed (a worker died), once it has
        self.restarts = 0                 # times its process was restarted by a supervisor (set by the runner)
        self._stats_report = Report(self.stats)
        self._stats_last: dict[str, Any] | None = None
        self._lock = threading.Lock()     # guards warnings and failing across threads
        self._last_warning: dict[str, float] = {}
        self._bus: Bus | None = None
        self._threads: list[threading.Thread] = []
        self._entities: list[Any] = []
        self._queues: list[SampleQueue] = []  # whose consumers must keep taking (see health)
        self._stats_beat = 0.0            # when the stats worker last went round (monotonic)
        self._on_stopping: list[Callable[[], None]] = []  # told once ``stopping`` is set (when_stopping)
        self._on_failed: list[Callable[[], None]] = []    # told once the node failed (when_failed)

    @property
    def bus(self) -> Bus:
        if self._bus is None:
            raise RuntimeError(f"{self!r} is not started")
        return self._bus

    def start(self, bus: Bus) -> None:
        """Join the bus and begin work; on failure everything taken is given back."""
        if self.state != "new":
            raise RuntimeError(f"{self!r} cannot start: it is {self.state}")
        self._bus = bus.for_node(self.name)
        self._bus.on_error = self._callback_failed
        self.state = "starting"
        self.since = time.time()
        self._stats_report = Report(self.stats)  # (its first interval starts now)
        try:
            node_key = keys.node_token(self._bus.host, self.name)
            self.own(self._bus.token(node_key))
            self.own(self._bus.serve(node_key, lambda q: q.reply(node_key, codec.encode(self.describe()),
                                                                 encoding=codec.ENCODING)))
            self._start()
            self._publish_stats()
        except BaseException:
            self.stop()
            raise
        if self.state == "starting":  # (a worker may have failed already)
            self.state = "running"

    def stop(self) -> None:
        """Stop work and leave the bus; safe to call twice."""
        if self.state in ("new", "stopped"):
            self.state = "stopped"
            return
        self.stopping.set()
        log.info("%s: stopping; %s", self.name, ", ".join(f"{k} {v}" for k, v in self.stats.items()))
        try:
            for wake in list(self._on_stopping):
                try:
                    wake()
                except Exception:  # (one wake that fails must not keep the node's own stop from running)
                    self.count("errors")
                    log.exception("%s: waking a worker at the stop failed", self.name)
            self._stop()
        finally:
            for thread in self._threads:
                if thread.ident is None:  # Ctrl-C between spawn's append and start: it never ran
                    continue
                thread.join(JOIN_TIMEOUT_S)
                if thread.is_alive():
                    log.warning("%s: thread %s did not stop within %.0f s", self.name, thread.name, JOIN_TIMEOUT_S)
            for entity in reversed(self._entities):
                _undeclare(entity)
            self._entities.clear()
            self.state = "stopped"

    @classmethod
    def owned_robots(cls, config: Any) -> tuple[str, ...]:
        """The robots a node with ``config`` will own, known before it starts (a file
        with two owners of one robot is refused when it is loaded); default none."""
        return ()

    def describe(self) -> dict[str, Any]:
        """What ``sonibus nodes`` shows of this node (served on its node key)."""
        described = {"host": self.bus.host, "node": self.name, "adapter": self.kind, "robots": list(self.robots),
                     "since": self.since, "state": self.state}
        if self.failure:
            described["failure"] = self.failure
        return described

    def health(self) -> str:
        """Why this node is not healthy, or "" when it is: running (or paused: a recorder whose
        disk is nearly full must not have the show restarted), not failed, and not hung
        (its stats worker goes round every second; every queue it owns with items waiting
        is taken from within ``HANG_S``). ``sonibus run`` feeds a supervisor's watchdog
        only while every node is healthy. Safe from any thread."""
        if self.failure:
            return f"failed: {self.failure}"
        if self.state not in ("running", "paused"):  # (paused: waiting, by design, for what it needs to come back)
            return self.state
        still = time.monotonic() - self._stats_beat
        if still > HANG_S:
            return f"hung: its stats worker has not gone round for {still:.0f} s"
        for queue in self._queues:
            stalled = queue.stalled_s()
            if stalled > HANG_S:
                return f"hung: a worker has taken nothing from its queue for {stalled:.0f} s ({len(queue)} waiting)"
        return ""

    def claim_robot(self, robot: str, hint: str = "stop that node or give this robot another name") -> Ownership:
        """Become the owner of ``robot`` until stopped; ``OwnershipError`` if it has one.
        The ``Ownership`` says whether this node may act (it stands by while an earlier
        claim of the robot is on the bus) and publishes its frames."""
        ownership = self.own(Ownership(self.bus, robot, hint, self._claim_refused))
        ownership.take()
        self.robots.append(robot)
        return ownership

    def _claim_refused(self, key: str, why: str) -> None:
        """A claim of a robot this node owns that it does not take (``Ownership``): counted, warned."""
        self.count("claims_refused")
        self.warn("claim", why)

    def capped(self, what: str) -> None:
        """A name from the bus (a robot, a node, a key) this node did not keep because a table
        of its own is full: counted ``capped``, said at most once every ``WARN_EVERY_S``.
        Every table keyed by names from the bus has a cap: names made up must not grow it."""
        self.count("capped")
        self.warn("capped", f"{what} — names made up on the bus must not grow what this node keeps")

    def writes(self) -> list[str]:
        """The folders this node writes into, as configured (``sonibus service`` checks the show's
        user may): none, unless an adapter keeps files (a recorder's recordings)."""
        return []

    def resolve(self, path: str) -> str:
        """``path`` (a file or folder an option names) as this node opens it: a relative one is taken
        from the installation file's folder, as every path an installation file gives (the ``[log]``
        file, the ``[bus]`` TLS and users files), wherever ``sonibus run`` is started; as given for a
        node not built from a file (a command's own, ``sonibus record FILE``: from where it runs)."""
        if not path or self.folder is None:
            return path
        given = Path(path).expanduser()
        return str(given if given.is_absolute() else self.folder / given)

    def count(self, kind: str, n: int = 1) -> None:
        """Add ``n`` to counter ``kind`` of ``stats`` (safe from any thread)."""
        self.stats.add(kind, n)

    def record_latency(self, seconds: float) -> None:
        """Note one latency for the stats' p50/p99: a sink's now − the sample's ``t`` as it
        sends it, a robot's acquisition to publish (safe from any thread)."""
        self._stats_report.latencies.add(seconds)

    def metrics(self) -> dict[str, Any]:
        """Hook: figures of this kind of node for its stats (a file's size, per-target counts):
        numbers, strings, or maps of numbers. Called from the stats worker: read, do not block."""
        return {}

    def warn(self, kind: str, message: str) -> None:
        """Log a warning, at most one of each ``kind`` every ``WARN_EVERY_S`` (with the
        counters that are not zero): bad input at 100 Hz must not flood the log. Safe
        from any thread."""
        now = time.monotonic()
        with self._lock:
            if now - self._last_warning.get(kind, -math.inf) < WARN_EVERY_S:
                return
            self._last_warning[kind] = now
        counters = ", ".join(f"{k} {v}" for k, v in self.stats.items() if v)  # (outside the lock: reads sources)
        log.warning("%s: %s%s", self.name, message, f" ({counters})" if counters else "")

    def when_stopping(self, wake: Callable[[], None]) -> None:
        """Call ``wake()`` (on the stopping thread: it must not block) once ``stopping`` is set, at
        once if it is already: a worker that waits on something else than ``stopping`` (an event
        loop, a queue) is woken by it instead of looking at ``stopping`` every few milliseconds."""
        with self._lock:
            self._on_stopping.append(wake)
        if self.stopping.is_set():
            wake()

    def when_failed(self, wake: Callable[[], None]) -> None:
        """Call ``wake()`` (on the failing thread: it must not block) once the node has failed, at
        once if it has: ``sonibus run`` waits for that, or a stop, without looking every 0.1 s."""
        with self._lock:
            self._on_failed.append(wake)
            failed = bool(self.failure)
        if failed:
            wake()

    def spawn(self, target: Callable[[], None], name: str, restart: bool = False) -> threading.Thread:
        """Run ``target`` on a thread joined by ``stop()``; it must return once ``stopping``
        is set. If it raises, the node fails (see ``fail``) — or, with ``restart``, it
        is logged and run again after ``RESTART_AFTER_S``."""
        thread = threading.Thread(target=self._guard(target, name, restart), name=f"{self.name}:{name}",
                                  daemon=True)
        self._threads.append(thread)
        thread.start()
        return thread

    def _callback_failed(self, what: str, exc: BaseException) -> None:
        self.fail(f"{what} failed: {type(exc).__name__}: {_first_line(exc)}", exc)

    def fail(self, reason: str, exc: BaseException | None = None) -> None:
        """Mark the node failed, loudly: its state (``sonibus nodes``), a log line (with
        the traceback of ``exc``), and a ``node`` event on ``sonibus/events/node``;
        ``sonibus run`` then stops every node and ends with an error."""
        with self._lock:
            if self.failure:
                return
            self.failure = reason
            told = list(self._on_failed)
        self.state = "failed"
        self.count("errors")
        expected = isinstance(exc, SonibusError)  # a failure the code foresaw (a full disk): its line says it all
        log.error("%s: %s", self.name, reason, exc_info=None if expected else exc)
        if expected:
            log.debug("%s: %s", self.name, reason, exc_info=exc)
        if self._bus is not None:
            event = {"t": time.time(), "kind": "node", "host": self._bus.host, "node": self.name,
                     "adapter": self.kind, "state": "failed", "error": reason}
            try:
                self._bus.put(keys.NODE_EVENTS, event)
            except Exception as exc:  # the session may be closing: the log line and the state remain
                log.debug("%s: node event not sent: %s", self.name, exc)
        for wake in told:
            wake()

    def own(self, entity: Any) -> Any:
        """Undeclare/close ``entity`` (publisher, subscriber, token, queue...) on stop; a
        ``SampleQueue``'s drops count as the node's ``dropped``."""
        if isinstance(entity, SampleQueue):
            self.stats.follow("dropped", lambda: entity.dropped)
            self._queues.append(entity)
        self._entities.append(entity)
        return entity

    def _publish_stats(self) -> None:
        """Publish ``stats`` every ``STATS_EVERY_S`` and serve the latest on the same key
        (``bus/health.py``). Dropped under congestion; a missed second is only logged."""
        key = keys.node_stats(self.bus.host, self.name)
        publisher = self.own(self.bus.stream_publisher(key, STATS_QOS))
        self.own(self.bus.serve(key, lambda query: self._serve_stats(key, query)))

        def report() -> None:
            while not self.stopping.wait(STATS_EVERY_S):
                self._stats_beat = time.monotonic()  # (health: a metrics() that hangs stops the beat)
                try:
                    self._stats_last = self._stats_report.next(self._stats_identity(), self.metrics())
                    publisher.put(codec.encode(self._stats_last))
                except Exception as exc:  # a metrics() that raised, a closing session: the next second
                    if not self.stopping.is_set():
                        self.warn("stats", f"stats not sent: {type(exc).__name__}: {_first_line(exc)}")
        self._stats_beat = time.monotonic()  # (before its thread runs: the node is healthy from its start)
        self.spawn(report, "stats", restart=True)

    def _serve_stats(self, key: str, query: Any) -> None:
        """Answer with the stats last published (before the first: so far, the interval going on)."""
        try:
            stats = self._stats_last or self._stats_report.next(self._stats_identity(), self.metrics(),
                                                                advance=False)
            query.reply(key, codec.encode(stats), encoding=codec.ENCODING)
        except Exception as exc:  # (a metrics() that raised): the asker hears why at once, not a timeout
            self.warn("stats", f"stats not served: {type(exc).__name__}: {_first_line(exc)}")
            with contextlib.suppress(Exception):  # (a session closing underneath)
                query.reply_err(codec.encode({"error": f"stats of {self.name} unavailable: {_first_line(exc)}"}))

    def _stats_identity(self) -> dict[str, Any]:
        return {"host": self.bus.host, "node": self.name, "adapter": self.kind, "state": self.state,
                "since": self.since, "restarts": self.restarts}

    def _guard(self, target: Callable[[], None], name: str, restart: bool) -> Callable[[], None]:
        def run() -> None:
            while True:
                try:
                    target()
                    return
                except Exception as exc:
                    reason = f"worker '{name}' failed: {type(exc).__name__}: {_first_line(exc)}"
                    if not restart:
                        self.fail(reason, exc)
                        return
                    self.count("errors")
                    log.warning("%s: %s; restarting it in %g s", self.name, reason, RESTART_AFTER_S)
                    if self.stopping.wait(RESTART_AFTER_S):
                        return
        return run

    def _start(self) -> None:
        """Hook: declare what the adapter needs on ``self.bus``, spawn workers."""

    def _stop(self) -> None:
        """Hook: release what ``own`` and ``spawn`` do not cover."""

    def __enter__(self) -> Adapter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} {self.state}>"


def _first_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0] if lines else ""


def _undeclare(entity: Any) -> None:
    closer = getattr(entity, "undeclare", None) or getattr(entity, "close", None)
    try:
        if closer is not None:
            closer()
    except Exception as exc:  # a session closed underneath is not worth a traceback here
        log.debug("undeclare %r: %s", entity, exc)
