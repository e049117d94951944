"""Datagrams the kernel dropped on a UDP socket a node reads: its receive buffer was
full (what came was faster than the node read it), so they never reached the node.

Read from the socket's own drop counter (``getsockopt(SOL_SOCKET, SO_MEMINFO)``, Linux
4.10 and later: the ``drops`` column of ``/proc/net/udp`` for that socket), when asked —
once a second by the reader, never per datagram: the receive path costs nothing more.
Elsewhere the counter is unavailable: ``available`` is False and ``new()`` says 0.

>>> import socket
>>> with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
...     drops = KernelDrops(sock)
...     drops.new()
0
"""

from __future__ import annotations

import socket
import struct
import sys

SO_MEMINFO = 55        # <asm-generic/socket.h>: the socket's memory counters, an array of u32
SK_MEMINFO_DROPS = 8   # <linux/sock_diag.h>: the counter of datagrams dropped on the socket (sk_drops)
_WRAP = 1 << 32        # (a u32: it wraps)


class KernelDrops:
    """The kernel's drops on ``sock`` since this was made, read by ``new()``."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock
        self._last = self._read()
        self.available = self._last is not None
        self.total = 0

    def new(self) -> int:
        """Drops since the previous call (0 where the counter is unavailable, or the socket closed)."""
        now = self._read()
        if now is None or self._last is None:
            return 0
        found, self._last = (now - self._last) % _WRAP, now
        self.total += found
        return found

    def _read(self) -> int | None:
        if not sys.platform.startswith("linux"):
            return None
        try:
            raw = self._sock.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, 4 * (SK_MEMINFO_DROPS + 1))
        except OSError:  # a kernel without SO_MEMINFO, or a socket already closed
            return None
        if len(raw) < 4 * (SK_MEMINFO_DROPS + 1):  # (a kernel before 4.10: no drop counter in it)
            return None
        return int(struct.unpack_from("=I", raw, 4 * SK_MEMINFO_DROPS)[0])

    def __repr__(self) -> str:
        return f"<KernelDrops {self.total if self.available else 'unavailable'}>"
