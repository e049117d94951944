"""A stand-in for systemd's side of sd_notify: a unix datagram socket, read as systemd reads it."""

from __future__ import annotations

import os
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path


class Supervisor:
    """Binds ``path`` (or an abstract ``@name``) and keeps every datagram, parsed into
    ``{KEY: VALUE}`` with its arrival time, until ``close``."""

    def __init__(self, path: Path | str) -> None:
        self.address = str(path)
        self.socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.socket.bind(b"\0" + self.address[1:].encode() if self.address.startswith("@") else self.address)
        self.socket.settimeout(0.1)
        self.messages: list[tuple[float, dict[str, str]]] = []
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def environ(self, watchdog_s: float | None = None) -> dict[str, str]:
        """The variables systemd gives a ``Type=notify`` service (and ``WatchdogSec=``)."""
        env = {"NOTIFY_SOCKET": self.address}
        if watchdog_s is not None:
            env |= {"WATCHDOG_USEC": str(int(watchdog_s * 1e6)), "WATCHDOG_PID": str(os.getpid())}
        return env

    def _read(self) -> None:
        while not self._done.is_set():
            try:
                data = self.socket.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                return
            fields = dict(line.split("=", 1) for line in data.decode().splitlines())
            self.messages.append((time.monotonic(), fields))

    def with_key(self, key: str, since: float = 0.0) -> list[dict[str, str]]:
        return [m for t, m in list(self.messages) if key in m and t >= since]

    def statuses(self, since: float = 0.0) -> list[str]:
        return [m["STATUS"] for m in self.with_key("STATUS", since)]

    def after(self, predicate: Callable[[dict[str, str]], bool]) -> list[dict[str, str]]:
        """The messages from the first one ``predicate`` is true of, on."""
        messages = [m for _, m in list(self.messages)]
        first = next((i for i, m in enumerate(messages) if predicate(m)), len(messages))
        return messages[first:]

    def close(self) -> None:
        self._done.set()
        self._thread.join(1.0)
        self.socket.close()
        if not self.address.startswith("@"):
            Path(self.address).unlink(missing_ok=True)
