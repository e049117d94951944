"""A TCP relay between the naoqi adapter and a fake robot, for tests.

``Relay(port)`` forwards every connection to ``127.0.0.1:port``; with a
``ssl.SSLContext`` it terminates TLS first (a NAOqi 2.9 robot's ``tcps://``
endpoint in front of a plain fake). ``cut()`` makes the connections open now
go silent without closing — a Wi-Fi drop: bytes vanish both ways, no FIN, no
RST — while new connections go through again. ``sent`` holds the plaintext
the clients sent (what libqi put inside TLS)."""

from __future__ import annotations

import asyncio
import ssl
import subprocess
import threading
from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class _Connection:
    writers: list[asyncio.StreamWriter] = field(default_factory=list)
    cut: bool = False


class Relay:
    """Forwards ``127.0.0.1:<port>`` (see ``url``) to ``127.0.0.1:target``."""

    def __init__(self, target: int, tls: ssl.SSLContext | None = None) -> None:
        self.target, self.tls = target, tls
        self.port = 0
        self.sent = bytearray()
        self.accepted = 0                       # connections accepted (TLS handshake done, with tls)
        self._connections: list[_Connection] = []
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, name="relay", daemon=True)

    def url(self, scheme: str = "tcp") -> str:
        return f"{scheme}://127.0.0.1:{self.port}"

    def start(self) -> Relay:
        self._thread.start()
        if not self._ready.wait(5.0):
            raise RuntimeError("the relay did not start")
        return self

    def cut(self) -> None:
        """The connections open now stop carrying anything, and stay open."""
        self._loop.call_soon_threadsafe(self._cut)

    def stop(self) -> None:
        if self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(5.0)

    def _cut(self) -> None:
        for connection in self._connections:
            connection.cut = True

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        server = self._loop.run_until_complete(asyncio.start_server(self._serve, "127.0.0.1", 0, ssl=self.tls))
        self.port = server.sockets[0].getsockname()[1]
        self._ready.set()
        try:
            self._loop.run_forever()
        finally:
            server.close()
            for connection in self._connections:
                for writer in connection.writers:
                    writer.transport.abort()
            pending = asyncio.all_tasks(self._loop)  # (connections still pumping: ended, not left to the collector)
            for task in pending:
                task.cancel()
            self._loop.run_until_complete(asyncio.gather(*pending, asyncio.sleep(0), return_exceptions=True))
            self._loop.close()

    async def _serve(self, client_in: asyncio.StreamReader, client_out: asyncio.StreamWriter) -> None:
        self.accepted += 1
        try:
            robot_in, robot_out = await asyncio.open_connection("127.0.0.1", self.target)
        except OSError:
            client_out.transport.abort()
            return
        connection = _Connection([client_out, robot_out])
        self._connections.append(connection)
        await asyncio.gather(self._pump(client_in, robot_out, connection, self.sent),
                             self._pump(robot_in, client_out, connection, None), return_exceptions=True)

    @staticmethod
    async def _pump(source: asyncio.StreamReader, sink: asyncio.StreamWriter, connection: _Connection,
                    record: bytearray | None) -> None:
        while data := await source.read(65536):
            if connection.cut:
                continue  # swallowed, as by a dead network; the other side is told nothing
            if record is not None:
                record.extend(data)
            sink.write(data)
            await sink.drain()
        if not connection.cut:
            sink.close()


def self_signed(directory: Path, host: str = "127.0.0.1") -> ssl.SSLContext:
    """A server context with a fresh self-signed certificate made by ``openssl``, as robots have."""
    cert, key = directory / "robot.crt", directory / "robot.key"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2",
                    "-subj", f"/CN={host}", "-keyout", str(key), "-out", str(cert)],
                   check=True, capture_output=True, timeout=30)
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.load_cert_chain(cert, key)
    return context
