"""Telling systemd how a service is doing: its notification protocol (``sd_notify``).

systemd starts a ``Type=notify`` service with ``$NOTIFY_SOCKET``, a unix datagram
socket (a path, or ``@name`` in the abstract namespace), and reads ``KEY=VALUE``
lines from it: ``READY=1`` (started), ``STATUS=...`` (shown by ``systemctl
status``), ``WATCHDOG=1`` (alive: with ``WatchdogSec=``, a service silent for
longer is killed and restarted), ``EXTEND_TIMEOUT_USEC=...`` (still starting),
``STOPPING=1``. Outside systemd there is no socket and every call does nothing.

>>> Notifier({}).send(READY=1)   # not under systemd: nothing to tell
False

The protocol is one datagram per message (man sd_notify); the Python packages that
wrap it are either unmaintained (sdnotify, last release 2017) or need libsystemd's
headers to build (systemd-python), so it is done here.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
from collections.abc import Mapping

log = logging.getLogger(__name__)


class Notifier:
    """Messages to the supervisor at ``$NOTIFY_SOCKET`` (``environ``: default the
    process's environment). ``watchdog_s`` is the watchdog's timeout when systemd
    expects ``WATCHDOG=1`` from this process (``$WATCHDOG_USEC``), else None."""

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        self.address = _address(env.get("NOTIFY_SOCKET", ""))
        self.watchdog_s = _watchdog_s(env)
        self._socket: socket.socket | None = None
        self._lock = threading.Lock()
        self._warned = False

    @property
    def enabled(self) -> bool:
        """Whether a supervisor listens (``$NOTIFY_SOCKET`` is set)."""
        return bool(self.address)

    def send(self, **fields: object) -> bool:
        """Send ``KEY=VALUE`` lines in one datagram (``send(READY=1, STATUS="running")``);
        whether it went out. A refused send is logged once (the supervisor's watchdog,
        if any, will notice what it misses) and never raises."""
        if not self.address:
            return False
        text = "\n".join(f"{key}={' '.join(str(value).split())}" for key, value in fields.items())
        try:
            with self._lock:
                if self._socket is None:
                    self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
                self._socket.sendto(text.encode("utf-8", "replace"), self.address)
        except OSError as exc:
            if not self._warned:
                self._warned = True
                log.warning("cannot notify the supervisor at NOTIFY_SOCKET=%s: %s", _shown(self.address), exc)
            return False
        return True

    def close(self) -> None:
        with self._lock:
            if self._socket is not None:
                self._socket.close()
                self._socket = None

    def __repr__(self) -> str:
        where = _shown(self.address) if self.address else "no supervisor"
        return f"<Notifier {where} watchdog {self.watchdog_s}>"


def _address(value: str) -> str | bytes:
    """The socket address of ``$NOTIFY_SOCKET``: a path, or ``@name`` (abstract: a NUL first)."""
    if value.startswith("@"):
        return b"\0" + value[1:].encode()
    if value.startswith("/"):
        return value
    if value:  # (vsock:... of systemd 254+ for VMs: not for a show machine)
        log.warning("NOTIFY_SOCKET=%s is not a unix socket path or @name: systemd will not hear this process", value)
    return ""


def _watchdog_s(env: Mapping[str, str]) -> float | None:
    """``$WATCHDOG_USEC`` in seconds, when it is meant for this process (``$WATCHDOG_PID``
    absent or ours, as sd_watchdog_enabled checks); else None."""
    pid = env.get("WATCHDOG_PID", "")
    if pid and pid != str(os.getpid()):
        return None
    try:
        usec = int(env.get("WATCHDOG_USEC", ""))
    except ValueError:
        return None
    return usec / 1e6 if usec > 0 else None


def _shown(address: str | bytes) -> str:
    return "@" + address[1:].decode(errors="replace") if isinstance(address, bytes) else address
