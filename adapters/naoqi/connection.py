"""One libqi session to a robot: connect with a deadline, call with a deadline,
notice the loss, connect again on the same session.

Every call goes out with ``_async=True`` and is waited for with a timeout, so
nothing the adapter does can hang on a robot that stopped answering."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from .config import NaoqiConfig

log = logging.getLogger(__name__)

LINK_ERRORS = ("Session closed", "Socket is not connected", "no answer within", "disconnected", "not connected")


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
    """A qi session to ``config.endpoint``; ``on_lost(reason)`` runs when it breaks."""

    def __init__(self, config: NaoqiConfig, on_lost: Callable[[str], None]) -> None:
        try:
            import qi
        except ImportError:
            raise ImportError("the naoqi adapter needs libqi: pip install 'sonibus[naoqi]' (PyPI qi 3.1.5)") from None
        self.url = config.endpoint
        self.timeout_ms = int(config.connect_timeout_s * 1000)
        self.on_lost = on_lost
        qi.logging.setLevel(qi.logging.ERROR)  # libqi's chatter on stderr; our own log says what matters
        self.session = qi.Session()
        if config.password:
            self.session.setClientAuthenticatorFactory(AuthenticatorFactory(config.user, config.password))
        self.connected = False
        self._lock = threading.Lock()
        self._services: dict[str, Any] = {}
        self._signals: list[tuple[Any, int]] = []
        self._kept: list[Any] = []
        self._watch = self.session.disconnected.connect(self._disconnected)

    # -- connecting ---------------------------------------------------------------

    def connect(self, stopping: threading.Event) -> None:
        """Connect (again), or raise ``LinkDown``; gives up at once when ``stopping`` is set."""
        self.drop()
        future = self.session.connect(self.url, _async=True)
        deadline = time.monotonic() + self.timeout_ms / 1000.0
        while not future.isFinished():
            if stopping.is_set():
                raise LinkDown("stopping")
            if time.monotonic() > deadline:
                raise LinkDown(f"no answer within {self.timeout_ms / 1000.0:g} s")
            future.wait(50)
        if future.hasError():
            raise LinkDown(one_line(future.error()))
        self.connected = True

    def drop(self) -> None:
        """Forget the current connection (signals, services) and close the socket."""
        with self._lock:
            self.connected = False
            signals, self._signals, self._kept, self._services = self._signals, [], [], {}
        for signal, link_id in signals:
            try:
                signal.disconnect(link_id)
            except Exception as exc:  # the link is gone already
                log.debug("disconnect signal: %s", exc)
        try:
            self.session.close()
        except Exception as exc:
            log.debug("close session: %s", exc)

    def close(self) -> None:
        """Drop the connection for good (the adapter stops)."""
        self.drop()
        try:
            self.session.disconnected.disconnect(self._watch)
        except Exception as exc:
            log.debug("disconnect watch: %s", exc)

    def _disconnected(self, reason: Any = "") -> None:
        with self._lock:
            was, self.connected = self.connected, False
        if was:  # a close of our own, or a stale signal of an earlier connection, is not a loss
            self.on_lost(one_line(reason) if reason else "disconnected")

    def lost(self, reason: str) -> None:
        """Mark the link broken after a failed call (the signal may come later, or never)."""
        self._disconnected(reason)

    # -- calling --------------------------------------------------------------------

    def service(self, name: str) -> Any:
        proxy = self._services.get(name)
        if proxy is None:
            proxy = self.wait(self.session.service(name, _async=True), f"service {name}")
            self._services[name] = proxy
        return proxy

    def start(self, service: str, method: str, *args: Any) -> Any:
        """Send a call; its ``qi.Future``."""
        if not self.connected:
            raise LinkDown("not connected")
        try:
            return getattr(self.service(service), method)(*args, _async=True)
        except AttributeError:
            raise RemoteError(f"{service} has no method {method}") from None

    def call(self, service: str, method: str, *args: Any, timeout_ms: int | None = None) -> Any:
        """Call and wait (at most the connect timeout); ``RemoteError`` or ``LinkDown``."""
        return self.wait(self.start(service, method, *args), f"{service}.{method}", timeout_ms)

    def wait(self, future: Any, what: str, timeout_ms: int | None = None) -> Any:
        timeout_ms = timeout_ms or self.timeout_ms
        try:
            return future.value(timeout_ms)
        except RuntimeError as exc:
            message = one_line(exc)
            if message.startswith("Future timeout"):
                message = f"no answer within {timeout_ms / 1000:g} s"
            if any(m in message for m in LINK_ERRORS) or not self.session.isConnected():
                raise LinkDown(f"{what}: {message}") from None
            raise RemoteError(f"{what}: {message}") from None

    def try_call(self, service: str, method: str, *args: Any) -> Any:
        """A call whose failure only means "not available here" (None)."""
        try:
            return self.call(service, method, *args)
        except RemoteError as exc:
            log.debug("%s", exc)
            return None

    def on_signal(self, service: str, signal: str, callback: Callable[..., None]) -> None:
        try:
            proxy = getattr(self.service(service), signal)
        except AttributeError:
            raise RemoteError(f"{service} has no signal {signal}") from None
        self._signals.append((proxy, proxy.connect(callback)))

    def subscribe(self, key: str, callback: Callable[[Any], None]) -> None:
        """``ALMemory.subscriber(key).signal``; ``RemoteError`` where NAOqi refuses it."""
        subscriber = self.call("ALMemory", "subscriber", key)
        self._kept.append(subscriber)  # the subscription lives as long as this object
        self._signals.append((subscriber.signal, subscriber.signal.connect(callback)))
