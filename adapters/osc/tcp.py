"""OSC over TCP for the gateway: one thread accepts clients and reads their frames."""

from __future__ import annotations

import contextlib
import selectors
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from . import wire

MAX_CONNECTIONS = 64


@dataclass(frozen=True)
class Peer:
    """Where a packet came from: a UDP address, or a TCP connection."""

    address: tuple[Any, ...]
    connection: Connection | None = None


class Connection:
    """One TCP client; replies are framed as its requests are."""

    def __init__(self, sock: socket.socket, address: tuple[Any, ...]) -> None:
        self.sock, self.address, self.stream = sock, address, wire.Stream()

    def send(self, packet: bytes) -> None:
        """Send one packet (from the reply thread); a client that does not read is cut off."""
        try:
            self.sock.sendall(self.stream.frame(packet))
        except OSError:
            with contextlib.suppress(OSError):
                self.sock.shutdown(socket.SHUT_RDWR)  # the reading thread sees the end and closes it
            raise


def serve(listener: socket.socket, stopping: threading.Event, allowed: Callable[[str], bool],
          packet: Callable[[bytes, Peer], None], problem: Callable[[wire.WireError], None],
          refused: Callable[[str], None], poll_s: float = 0.2) -> None:
    """Accept clients on ``listener`` and hand each frame to ``packet`` until ``stopping``;
    a frame that cannot be read goes to ``problem``, a client over the limit to ``refused``."""
    with selectors.DefaultSelector() as selector:
        selector.register(listener, selectors.EVENT_READ)
        try:
            while not stopping.is_set():
                for key, _ in selector.select(poll_s):
                    if key.data is None:
                        _accept(listener, selector, allowed, refused, poll_s)
                    else:
                        _read(selector, key.data, packet, problem)
        finally:
            for key in list(selector.get_map().values()):
                if key.data is not None:
                    key.data.sock.close()


def _accept(listener: socket.socket, selector: selectors.BaseSelector, allowed: Callable[[str], bool],
            refused: Callable[[str], None], poll_s: float) -> None:
    try:
        sock, source = listener.accept()
    except OSError:
        return
    if not allowed(source[0]):
        sock.close()
        return
    if len(selector.get_map()) > MAX_CONNECTIONS:
        refused(f"TCP client {source[0]} refused: {MAX_CONNECTIONS} connections are open")
        sock.close()
        return
    sock.settimeout(poll_s)
    selector.register(sock, selectors.EVENT_READ, Connection(sock, source))


def _read(selector: selectors.BaseSelector, connection: Connection, packet: Callable[[bytes, Peer], None],
          problem: Callable[[wire.WireError], None]) -> None:
    items: list[bytes | wire.WireError] | None = None
    try:
        data = connection.sock.recv(65536)
        items = connection.stream.feed(data) if data else None
    except wire.WireError as exc:  # the stream cannot be followed any more
        problem(exc)
    except OSError:
        pass
    if items is None:
        selector.unregister(connection.sock)
        connection.sock.close()
        return
    peer = Peer(connection.address, connection)
    for item in items:
        if isinstance(item, wire.WireError):
            problem(item)
        else:
            packet(item, peer)
