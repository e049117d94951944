"""One libqi session to a robot: connect with a deadline, call with a deadline,
notice the loss, connect again on the same session.

Every call goes out with ``_async=True`` — also connecting and disconnecting
signals, unsubscribing and closing — and is waited for with a bound, so nothing
the adapter does can hang on a robot that stopped answering (frozen, or a link
that vanished without closing).

libqi crashed the process (a segfault in one of its own threads) when a call
was sent on a session that another thread was closing, or once a closed
session was freed while work on it was still in flight. So calls are sent
only on the current session and never while it is being closed, and a closed
session is kept for ``RETIRE_S`` before Python may free it."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import qi  # here, not at connect: without the naoqi extra the registry lists this adapter with what to install

from .config import NaoqiConfig

log = logging.getLogger(__name__)

DROP_MS = 500  # a drop waits this long at most for the robot to hear goodbye
POLL_S = 0.05  # a wait on the robot looks at ``stopping`` this often
RETIRE_S = 30.0  # a closed session is freed no sooner: far longer than any call on it can wait
LINK_ERRORS = ("Session closed", "Socket is not connected", "no answer within", "disconnected", "not connected",
               "Future has already been set")  # (libqi's words for a call cut short by a closing session)


_retired: list[tuple[float, Any]] = []  # closed sessions, of every link: (monotonic time they may be freed, session)
_retired_lock = threading.Lock()


def _retire(session: Any) -> None:
    """Keep closed ``session`` for ``RETIRE_S`` (past its ``Link`` too: the node's threads
    stop after the link closes), and let those kept long enough go."""
    now = time.monotonic()
    with _retired_lock:
        _retired[:] = [(free_at, old) for free_at, old in _retired if free_at > now]
        _retired.append((now + RETIRE_S, session))


class LinkDown(Exception):
    """The robot cannot be reached (connect failed, the link broke, a call timed out)."""


class RemoteError(Exception):
    """The robot answered a call with an error (message on one line)."""


def one_line(error: Any) -> str:
    """A libqi/NAOqi error message on one line (no Python traceback, no tabs)."""
    lines = []
    for line in str(error).splitlines():
        if line.strip() == "At:":
            break
        if line.strip():
            lines.append(line.strip().removeprefix("RuntimeError: "))
    return ": ".join(lines) or type(error).__name__


class Authenticator:
    """NAOqi 2.9 login: libqi asks the factory for one of these per connection."""

    def __init__(self, user: str, password: str) -> None:
        self.user, self.password = user, password

    def initialAuthData(self) -> dict[str, str]:  # the name libqi calls
        return {"user": self.user, "token": self.password}


class AuthenticatorFactory:
    def __init__(self, user: str, password: str) -> None:
        self.user, self.password = user, password

    def newAuthenticator(self) -> Authenticator:  # the name libqi calls
        return Authenticator(self.user, self.password)


class Link:
    """A qi session to ``config.endpoint``; ``on_lost(reason)`` runs when it breaks.

    Every wait on the robot is bounded, and ends early once ``stopping`` is set:
    calls by their timeout, a drop (unsubscribing, closing) by ``DROP_MS``. Each
    connection gets a session of its own, so nothing left of a dead link (a
    connect or a goodbye the robot never answered) stands in the next one's way."""

    def __init__(self, config: NaoqiConfig, on_lost: Callable[[str], None],
                 stopping: threading.Event | None = None) -> None:
        self._qi = qi
        self.url = config.endpoint
        self.timeout_ms = int(config.connect_timeout_s * 1000)
        self.on_lost = on_lost
        self.stopping = stopping if stopping is not None else threading.Event()
        qi.logging.setLevel(qi.logging.ERROR)  # libqi's chatter on stderr; our own log says what matters
        self._factory = AuthenticatorFactory(config.user, config.password) if config.password else None
        self.session: Any = None
        self.connected = False
        self._generation = 0  # which session is current: signals of older ones are ignored
        self._closed = False  # for good: no session is opened any more
        self._lock = threading.Lock()
        self._sending = threading.Lock()  # held while a call is sent on a session, and while one is closed
        self._services: dict[str, Any] = {}
        self._signals: list[tuple[Any, int]] = []
        self._kept: list[Any] = []

    # -- connecting ---------------------------------------------------------------

    def connect(self) -> None:
        """Connect (again) on a new session, or raise ``LinkDown``; gives up at once when stopping."""
        self.drop()
        session = self._qi.Session()
        if self._factory is not None:
            session.setClientAuthenticatorFactory(self._factory)
        with self._lock:
            if self._closed:  # (a reader that was connecting when the adapter stopped)
                raise LinkDown("connect: the link is closed")
            self._generation += 1
            generation = self._generation
        # set up before other threads see the session (nobody closes it meanwhile); connecting
        # is sent like any call: never while a drop closes it, not at all once dropped
        session.disconnected.connect(lambda reason="": self._disconnected(reason, generation))
        with self._lock:
            if generation == self._generation:
                self.session = session
        self.wait(self.send(generation, session.connect, self.url), "connect")
        with self._lock:
            if self._generation != generation:  # dropped while it connected: not connected, and says so
                raise LinkDown("connect: the link was dropped meanwhile")
            self.connected = True

    def drop(self) -> None:
        """Forget the current connection (signals, services) and close it, waiting at most
        ``DROP_MS`` in all: a robot that stopped answering holds up neither a stop nor the
        next connection. A link already lost is closed without a word to the robot."""
        with self._lock:
            live, self.connected = self.connected, False
            session, self.session = self.session, None
            signals, self._signals, self._kept, self._services = self._signals, [], [], {}
            self._generation += 1
        if session is None:
            return
        deadline = time.monotonic() + DROP_MS / 1000.0
        goodbyes = []
        for signal, link_id in signals if live else ():
            try:
                with self._sending:
                    goodbyes.append(signal.disconnect(link_id, _async=True))
            except Exception as exc:  # the link is gone already
                log.debug("disconnect signal: %s", exc)
        with self._sending:
            try:
                goodbyes.append(session.close(_async=True))  # fails whatever still waits on this session
            except Exception as exc:
                log.debug("close session: %s", exc)
        _retire(session)
        for future in goodbyes:
            if not future.isFinished():
                future.wait(max(0, int((deadline - time.monotonic()) * 1000)))

    def close(self) -> None:
        """Drop the connection for good (the adapter stops): a connect under way, or tried
        later, opens nothing (``LinkDown``)."""
        with self._lock:
            self._closed = True
        self.drop()

    def _disconnected(self, reason: Any, generation: int) -> None:
        with self._lock:
            if generation != self._generation:  # a close of our own, or an earlier session's signal
                return
            was, self.connected = self.connected, False
        if was:
            self.on_lost(one_line(reason) if reason else "disconnected")

    def lost(self, reason: str) -> None:
        """Mark the link broken after a failed call (the signal may come later, or never)."""
        with self._lock:
            generation = self._generation
        self._disconnected(reason, generation)

    # -- calling --------------------------------------------------------------------

    def service(self, name: str) -> Any:
        """The proxy of service ``name`` on the current session (asked for once per session)."""
        with self._lock:
            proxy, session, generation = self._services.get(name), self.session, self._generation
        if proxy is None:
            if session is None:
                raise LinkDown("not connected")
            proxy = self.wait(self.send(generation, session.service, name), f"service {name}")
            with self._lock:
                if generation != self._generation:  # dropped meanwhile: not a proxy for the next session
                    raise LinkDown(f"service {name}: the link was replaced")
                self._services[name] = proxy
        return proxy

    def current(self) -> tuple[int, Any]:
        """(generation, session) of the current connection; ``LinkDown`` when there is none."""
        with self._lock:
            if self.session is None:
                raise LinkDown("not connected")
            return self._generation, self.session

    def send(self, generation: int | None, method: Callable[..., Any], *args: Any) -> Any:
        """``method(*args, _async=True)`` on session ``generation``'s objects: its ``qi.Future``,
        or ``LinkDown`` if that session is no longer the current one (``None``: any session,
        a goodbye to an old one)."""
        with self._sending:
            if generation is not None and (generation != self._generation or self.session is None):
                raise LinkDown("not connected (the link was replaced)")
            return method(*args, _async=True)

    def start(self, service: str, method: str, *args: Any) -> Any:
        """Send a call; its ``qi.Future``."""
        if not self.connected:
            raise LinkDown("not connected")
        generation = self._generation
        try:
            bound = getattr(self.service(service), method)
        except AttributeError:
            raise RemoteError(f"{service} has no method {method}") from None
        return self.send(generation, bound, *args)

    def call(self, service: str, method: str, *args: Any, timeout_ms: int | None = None,
             interruptible: bool = True) -> Any:
        """Call and wait (at most the connect timeout); ``RemoteError`` or ``LinkDown``."""
        return self.wait(self.start(service, method, *args), f"{service}.{method}", timeout_ms, interruptible)

    def wait(self, future: Any, what: str, timeout_ms: int | None = None, interruptible: bool = True) -> Any:
        """The value of ``future``; ``LinkDown`` after ``timeout_ms`` (default: the connect timeout)
        or once stopping (unless not ``interruptible``: a last call on the way out)."""
        timeout_ms = timeout_ms or self.timeout_ms
        deadline = time.monotonic() + timeout_ms / 1000.0
        while not future.isFinished():
            if interruptible and self.stopping.is_set():
                raise LinkDown(f"{what}: stopping")
            left = deadline - time.monotonic()
            if left <= 0:
                raise LinkDown(f"{what}: no answer within {timeout_ms / 1000:g} s")
            future.wait(max(1, int(min(left, POLL_S) * 1000)))
        if not future.hasError():
            return future.value()
        message = one_line(future.error())
        session = self.session
        if any(m in message for m in LINK_ERRORS) or session is None or not session.isConnected():
            raise LinkDown(f"{what}: {message}")
        raise RemoteError(f"{what}: {message}")

    def try_call(self, service: str, method: str, *args: Any) -> Any:
        """A call whose failure only means "not available here" (None)."""
        try:
            return self.call(service, method, *args)
        except RemoteError as exc:
            log.debug("%s", exc)
            return None

    def on_signal(self, service: str, signal: str, callback: Callable[..., None]) -> None:
        generation = self._generation
        try:
            proxy = getattr(self.service(service), signal)
        except AttributeError:
            raise RemoteError(f"{service} has no signal {signal}") from None
        self._connect(generation, proxy, callback, f"{service}.{signal}")

    def subscribe(self, key: str, callback: Callable[[Any], None]) -> None:
        """``ALMemory.subscriber(key).signal``; ``RemoteError`` where NAOqi refuses it."""
        generation = self._generation
        subscriber = self.call("ALMemory", "subscriber", key)
        self._connect(generation, subscriber.signal, callback, f"subscriber({key}).signal", keep=subscriber)

    def _connect(self, generation: int, signal: Any, callback: Callable[..., None], what: str,
                 keep: Any = None) -> None:
        link_id = self.wait(self.send(generation, signal.connect, callback), what)
        with self._lock:
            if generation != self._generation:  # dropped meanwhile: its session is closed, with the signal
                raise LinkDown(f"{what}: the link was replaced")
            self._signals.append((signal, link_id))
            if keep is not None:
                self._kept.append(keep)  # the subscription lives as long as this object
