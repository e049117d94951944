"""Independent OSC receivers for tests: headless Pure Data (Debian package
``puredata-core``), liblo's ``oscdump`` and a plain UDP socket that keeps every datagram.

A patch is written to a file, Pd runs it with ``-nogui -nosound -nomidi -stderr``
and every ``[print NAME]`` shows up as a line ``NAME: ...`` in the process's
``lines``. ``start_pd`` returns once the patch is loaded and listening: a
``[loadbang]`` → ``[print READY]`` fires after every object (and so
``[netreceive]``'s socket) is created, and errors printed before it, such as a
port already in use, fail the test.

What Pd 0.53's ``[oscparse]`` does, checked by the tests: it splits the address
into symbols (``/pepper/joints/HeadYaw`` → ``pepper joints HeadYaw``), keeps
string arguments as symbols (``/HeadYaw``), unpacks bundles into their messages
at once (the timetag is ignored), and does not know the ``d`` (double) tag.
"""

from __future__ import annotations

import itertools
import socket
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from ..conftest import require_tool, wait_for

PD_ARGS = ("-nogui", "-nosound", "-nomidi", "-stderr")
READY = "READY: bang"


class Patch:
    """A patch built object by object; ``obj`` returns the object's index for ``connect``."""

    def __init__(self) -> None:
        self._lines = ["#N canvas 0 0 900 700 12;"]
        self._count = 0

    def obj(self, *atoms: object) -> int:
        x, y = 10 + 220 * (self._count // 20), 10 + 30 * (self._count % 20)
        self._lines.append(f"#X obj {x} {y} {' '.join(str(a) for a in atoms)};")
        self._count += 1
        return self._count - 1

    def connect(self, source: int, outlet: int, sink: int, inlet: int = 0) -> None:
        self._lines.append(f"#X connect {source} {outlet} {sink} {inlet};")

    def chain(self, *objects: int) -> int:
        """Connect each object's first outlet to the next one's first inlet; the last object."""
        for source, sink in itertools.pairwise(objects):
            self.connect(source, 0, sink)
        return objects[-1]

    def text(self) -> str:
        return "\n".join(self._lines) + "\n"


def osc_input(patch: Patch, port: int) -> int:
    """``[netreceive -u -b PORT]`` → ``[oscparse]`` → ``[list trim]``; the ``[list trim]``."""
    return patch.chain(patch.obj("netreceive", "-u", "-b", port), patch.obj("oscparse"),
                       patch.obj("list", "trim"))


def receiver_patch(port: int, name: str = "OSC") -> Patch:
    """Print every OSC message arriving on ``port``: ``OSC: pepper joints HeadYaw 0.25``."""
    patch = Patch()
    patch.chain(osc_input(patch, port), patch.obj("print", name))
    return patch


def pepperosc_patch(port: int, joint: str = "HeadYaw") -> Patch:
    """The receiving side of PepperOSC's own Pd patch.

    ``[route pepperdata soundstart soundstop]``; pepperdata → ``[route /HeadYaw /latency]``
    → ``[route /PositionSensor]`` → ``[print HeadYaw]``; ``[print latency]``,
    ``[print soundstart]``, ``[print soundstop]``."""
    patch = Patch()
    parsed = osc_input(patch, port)
    top = patch.obj("route", "pepperdata", "soundstart", "soundstop")
    patch.connect(parsed, 0, top)
    data = patch.obj("route", f"/{joint}", "/latency")
    patch.connect(top, 0, data)
    patch.chain(data, patch.obj("route", "/PositionSensor"), patch.obj("print", joint))
    patch.connect(data, 1, patch.obj("print", "latency"))
    patch.connect(top, 1, patch.obj("print", "soundstart"))
    patch.connect(top, 2, patch.obj("print", "soundstop"))
    return patch


def start_pd(spawn: Callable[..., Any], tmp_path: Path, patch: Patch, name: str = "receiver.pd",
             timeout: float = 10.0) -> Any:
    """Run ``patch`` in headless Pd; returns the process (``.lines``: what Pd printed) once it listens."""
    pd = require_tool("pd", "puredata-core")
    ready = patch.obj("loadbang")
    patch.chain(ready, patch.obj("print", "READY"))
    path = tmp_path / name
    path.write_text(patch.text(), encoding="utf-8")
    # Pd prints on stderr; the spawn fixture collects stdout.
    process = spawn("sh", "-c", 'exec "$0" "$@" 2>&1', pd, *PD_ARGS, str(path), collect=True)
    wait_for(lambda: READY in process.lines or process.popen.poll() is not None, timeout,
             f"Pd to load {path.name}")
    lines = list(process.lines)
    if READY not in lines:
        pytest.fail(f"Pd ended before loading {path.name}: {lines}")
    errors = [line for line in lines[:lines.index(READY)] if "error" in line or "couldn't create" in line]
    if errors:
        pytest.fail(f"Pd could not load {path.name}: {errors}")
    return process


def printed(process: Any, name: str) -> list[str]:
    """What ``[print NAME]`` printed so far, without the ``NAME: `` prefix."""
    prefix = f"{name}: "
    return [line[len(prefix):] for line in list(process.lines) if line.startswith(prefix)]


def errors(process: Any) -> list[str]:
    """Error lines Pd printed (e.g. ``error: oscparse: unknown tag 'd' (100)``), and objects it
    could not create (Pd 0.53 prints ``... couldn't create`` without the word error)."""
    return [line for line in list(process.lines) if line.startswith("error") or "couldn't create" in line]


PROBE = "/sonibus/test/ready"


def start_oscdump(spawn: Callable[..., Any], port: int, timeout: float = 10.0) -> Any:
    """``oscdump -L PORT``, returned once it prints what it receives (a probe message it got)."""
    oscdump = require_tool("oscdump", "liblo-tools")
    process = spawn(oscdump, "-L", str(port), collect=True)
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        datagram = PROBE.encode() + b"\0" * (4 - len(PROBE) % 4) + b",\0\0\0"
        wait_for(lambda: probe.sendto(datagram, ("127.0.0.1", port)) and any(PROBE in line for line in process.lines),
                 timeout, "oscdump to listen")
    finally:
        probe.close()
    return process


def oscdump_lines(process: Any) -> list[str]:
    """What oscdump printed, without its readiness probes."""
    return [line for line in list(process.lines) if PROBE not in line]


SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux


class Datagrams:
    """A UDP socket on 127.0.0.1 that keeps every datagram with its arrival time
    (monotonic), and in ``stamps`` the kernel's receive time of each (epoch seconds:
    precise to microseconds whatever this process is doing)."""

    def __init__(self) -> None:
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.socket.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        self.stamps: list[float] = []
        self.socket.bind(("127.0.0.1", 0))
        self.socket.settimeout(0.05)
        self.port: int = self.socket.getsockname()[1]
        self.items: list[tuple[float, bytes]] = []
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._receive, daemon=True)
        self._thread.start()

    @property
    def target(self) -> str:
        return f"127.0.0.1:{self.port}"

    def data(self) -> list[bytes]:
        return [d for _, d in list(self.items)]

    def stamped(self) -> list[tuple[float, bytes]]:
        """Each datagram with the kernel's receive time: when it was sent, however late this
        process read it (on a busy machine reads come in bunches)."""
        items = list(self.items)
        return [(stamp, data) for stamp, (_, data) in zip(self.stamps[:len(items)], items, strict=True)]

    def _receive(self) -> None:
        while not self._closed.is_set():
            try:
                data, ancillary, _, _ = self.socket.recvmsg(65536, socket.CMSG_SPACE(16))
            except TimeoutError:
                continue
            except OSError:
                return
            for level, kind, raw in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                    seconds, nanoseconds = struct.unpack("qq", raw[:16])
                    self.stamps.append(seconds + nanoseconds / 1e9)
            self.items.append((time.monotonic(), data))

    def close(self) -> None:
        self._closed.set()
        self._thread.join(1.0)
        self.socket.close()
