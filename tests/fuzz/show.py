"""One ``sonibus run`` holding every built-in node, and what watches it.

``Show`` starts a private JACK server (dummy driver), two ``oscdump`` receivers,
then ``sonibus -v run show.toml`` on a private bus (multicast off, listening on
loopback) with ``sim``, ``osc`` (a plain and a bundle target), ``osc-gateway``,
``features``, ``recorder``, ``midi``, ``console`` and the three servers ``web``,
``oscquery`` and ``foxglove`` (small limits: ``serving.py``); it reads the MIDI port
back through JACK, samples the process's RSS from /proc, and opens a Zenoh
session of its own for the fuzzer. Everything is ended on ``close()``, also
after a failure, each process by its own process group.

No pytest here: ``bench/soak.py`` uses it too. Waiting that runs out raises
``ShowError``.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import rtmidi

from sonibus.bus import BusConfig, open_session

from .serving import CLIENTS, CONNECTIONS, TIMEOUT_S

SONIBUS = str(Path(sys.executable).with_name("sonibus"))
RATE_HZ = 50            # the simulated Pepper's frame rate
PEPPER_JOINTS = 17
NODES = ("sim", "osc", "gateway", "features", "recorder", "midi", "console", "web", "oscquery", "foxglove")
PROBE = "/fuzz/probe"
LIMITS = f"{{connections = {CONNECTIONS}, clients = {CLIENTS}, timeout_s = {TIMEOUT_S}}}"  # each server's


class ShowError(Exception):
    """The show could not be started, or a condition did not come in time."""


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def until(predicate: Callable[[], Any], timeout: float, what: str, step: float = 0.01) -> Any:
    """``predicate()`` once it is truthy; ``ShowError`` after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise ShowError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(step)


class Child:
    """A child process in its own process group; stdout and stderr read as they come
    (each line with ``time.monotonic()`` when read), so it never blocks on a pipe."""

    def __init__(self, args: list[str], env: dict[str, str] | None = None) -> None:
        self.args = args
        self.popen = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                      errors="replace", start_new_session=True, env=env)
        self.out: list[tuple[float, str]] = []
        self.err: list[tuple[float, str]] = []
        self._readers = [threading.Thread(target=self._read, args=(pipe, into), daemon=True)
                         for pipe, into in ((self.popen.stdout, self.out), (self.popen.stderr, self.err))]
        for reader in self._readers:
            reader.start()

    @staticmethod
    def _read(pipe: Any, into: list[tuple[float, str]]) -> None:
        for line in pipe:
            into.append((time.monotonic(), line.rstrip("\n")))

    @property
    def pid(self) -> int:
        return self.popen.pid

    @property
    def alive(self) -> bool:
        return self.popen.poll() is None

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int | None:
        """Signal it and wait; ``None`` if it had to be killed."""
        if self.alive:
            self.popen.send_signal(sig)
        try:
            code: int | None = self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            code = None
        self.kill()
        return code

    def kill(self) -> None:
        if self.popen.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.popen.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.popen.wait(5.0)
        for reader in self._readers:
            reader.join(2.0)

    def tail(self, lines: int = 15) -> str:
        state = "running" if self.alive else f"exited {self.popen.returncode}"
        shown = [text for _, text in (self.out[-lines:] + self.err[-lines:])]
        return f"{os.path.basename(self.args[0])} ({state}): " + " | ".join(shown)


_OSC_LINE = re.compile(r"^([0-9a-f]{8})\.([0-9a-f]{8}) (\S+) ?(.*)$")


class OscDump(Child):
    """``oscdump -L PORT``, ready once a probe sent to it came out."""

    def __init__(self, port: int) -> None:
        super().__init__(["oscdump", "-L", str(port)])
        self.port = port
        probe = _osc_message(PROBE)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            def seen() -> bool:
                s.sendto(probe, ("127.0.0.1", port))
                time.sleep(0.05)
                return any(PROBE in text for _, text in self.out) or not self.alive
            until(seen, 10, f"oscdump on udp {port}")
        if not self.alive:
            raise ShowError(f"oscdump on udp {port} ended: {self.tail()}")

    def count(self, prefix: str, since: float) -> int:
        """Messages whose address starts with ``prefix`` read at or after ``since`` (monotonic)."""
        n = 0
        for read, text in reversed(self.out):
            if read < since:
                break
            match = _OSC_LINE.match(text)
            if match is not None and match[3].startswith(prefix):
                n += 1
        return n


def _osc_message(address: str) -> bytes:
    def pad(b: bytes) -> bytes:
        b += b"\0"
        return b + b"\0" * (-len(b) % 4)
    return pad(address.encode()) + pad(b",")


_MIDI_CHILD = r"""
import json, sys, threading, time, rtmidi
midi = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, "fuzz-reader")
names = midi.get_ports()
wanted = [i for i, name in enumerate(names) if sys.argv[1] in name]
if not wanted:
    print(json.dumps(names), flush=True)
    raise SystemExit(0)
lock = threading.Lock()  # (a line whole: rtmidi's thread prints as soon as the port is open, beside "ready")
def say(line):
    with lock:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()
midi.set_callback(lambda event, _: say(f"{time.monotonic()} {event[0][0]}"))
midi.open_port(wanted[0], "in")
say("ready")
sys.stdin.read()  # (until the show closes it)
midi.close_port()
midi.delete()
"""


class MidiReader:
    """A JACK MIDI input connected to ``port``; each message's status byte with its
    ``time.monotonic()`` (one clock for every process of the machine). python-rtmidi's JACK
    input runs in a process of its own: its callback thread crashed the process that held it
    (SIGSEGV in _rtmidi: a soak's, and this test's worker, which took the whole run down)."""

    RESTARTS = 5  # a reader that dies is started again this often: its crash is not the node's silence

    def __init__(self, port: str) -> None:
        self.port, self.closing = port, False
        self.deaths: list[int | None] = []  # the exit status of each reader that died (said by ``died``)
        self.messages: list[tuple[float, list[int]]] = []
        self.child = self._spawn()
        self._reader = threading.Thread(target=self._read, name="midi-reader", daemon=True)
        self._reader.start()

    def _spawn(self) -> subprocess.Popen[str]:
        child = subprocess.Popen([sys.executable, "-c", _MIDI_CHILD, self.port], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, text=True)
        assert child.stdout is not None
        said = child.stdout.readline().strip()
        if said != "ready":
            self.child = child
            self.close()
            raise ShowError(f"no JACK MIDI port '{self.port}' among {said or '(the reader died)'}")
        return child

    def _read(self) -> None:
        while True:
            assert self.child.stdout is not None
            for line in self.child.stdout:
                read, _, status = line.partition(" ")
                with contextlib.suppress(ValueError):
                    self.messages.append((float(read), [int(status)]))
            if self.closing or len(self.deaths) >= self.RESTARTS:
                return
            self.deaths.append(self.child.wait())  # (its stdout ended: the reader died, not the node)
            try:
                self.child = self._spawn()
            except ShowError:
                return

    @property
    def died(self) -> str:
        """Whether the test's own reader died (and was started again): said beside a silence."""
        return f" (the test's MIDI reader died {len(self.deaths)} time(s), exit {self.deaths})" if self.deaths else ""

    def count(self, since: float, status_high: int | None = None) -> int:
        """Messages read at or after ``since``; ``status_high`` 0xB0 (CC) or 0xE0 (pitch bend) selects."""
        n = 0
        for read, message in reversed(self.messages):
            if read < since:
                break
            if status_high is None or message[0] & 0xF0 == status_high:
                n += 1
        return n

    def close(self) -> None:
        self.closing = True
        with contextlib.suppress(OSError, ValueError):
            self.child.stdin.close()  # type: ignore[union-attr]
        try:
            self.child.wait(3)
        except subprocess.TimeoutExpired:
            self.child.kill()
            self.child.wait()


class Rss:
    """The resident set size of a process, sampled every ``every_s`` from /proc, and the part
    of it that is shared memory (``RssShmem``: JACK's, and Zenoh's pools of 16 MiB in
    /dev/shm, mapped once a peer on this machine sends a payload over 3 KiB)."""

    def __init__(self, pid: int, every_s: float = 0.2) -> None:
        self.pid, self.samples = pid, []
        self.shmem: list[int] = []  # (beside each sample)
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(every_s,), daemon=True)
        self._thread.start()

    def now(self) -> int:
        """Bytes, or 0 once the process is gone."""
        return self._read()[0]

    def _read(self) -> tuple[int, int]:
        found = {}
        try:
            for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
                if line.startswith(("VmRSS:", "RssShmem:")):
                    found[line.split(":")[0]] = int(line.split()[1]) * 1024
        except OSError:
            pass
        return found.get("VmRSS", 0), found.get("RssShmem", 0)

    def _run(self, every_s: float) -> None:
        while not self._done.wait(every_s):
            value, shmem = self._read()
            if value:
                self.shmem.append(shmem)  # (first: a reader's zip never finds a sample without it)
                self.samples.append((time.monotonic(), value))

    def peak(self, since: float = 0.0) -> int:
        return max((v for t, v in self.samples if t >= since), default=0)

    def shmem_growth(self, since: float = 0.0) -> int:
        """``RssShmem`` in the sample of ``peak(since)`` less in the first sample since."""
        kept = [(v, s) for (t, v), s in zip(self.samples, self.shmem, strict=False) if t >= since]
        return max(kept, default=(0, 0))[1] - (kept[0][1] if kept else 0)

    def close(self) -> None:
        self._done.set()
        self._thread.join(2.0)


@dataclass
class Ports:
    bus: int = field(default_factory=free_port)
    gateway: int = field(default_factory=lambda: free_port(socket.SOCK_DGRAM))
    plain: int = field(default_factory=lambda: free_port(socket.SOCK_DGRAM))
    bundle: int = field(default_factory=lambda: free_port(socket.SOCK_DGRAM))
    web: int = field(default_factory=free_port)
    oscquery: int = field(default_factory=free_port)
    foxglove: int = field(default_factory=free_port)

    @property
    def endpoint(self) -> str:
        return f"tcp/127.0.0.1:{self.bus}"


def show_toml(ports: Ports, recording: Path) -> str:
    """The installation: every built-in node in one file, on a private bus."""
    return f"""\
[bus]
multicast = false
listen = ["{ports.endpoint}"]

[nodes.sim]
adapter = "sim"
robot = "pepper"
rate_hz = {RATE_HZ}
idle = true

[nodes.osc]
adapter = "osc"
targets = ["127.0.0.1:{ports.plain}", {{to = "127.0.0.1:{ports.bundle}", bundle = true}}]

[nodes.gateway]
adapter = "osc-gateway"
listen = "127.0.0.1:{ports.gateway}"

[nodes.features]
adapter = "features"
robots = "pepper"

[nodes.recorder]
adapter = "recorder"
path = "{recording}"
status_every_s = 1

[nodes.midi]
adapter = "midi"
api = "jack"
map = [{{key = "pepper/joints/HeadPitch", pitchbend = true, channel = 2}}]

[nodes.console]
adapter = "console"
every_s = 0.5

[nodes.web]
adapter = "web"
listen = "127.0.0.1:{ports.web}"
limits = {LIMITS}

[nodes.oscquery]
adapter = "oscquery"
listen = "127.0.0.1:{ports.oscquery}"
gateway = "127.0.0.1:{ports.gateway}"
mdns = false
limits = {LIMITS}

[nodes.foxglove]
adapter = "foxglove"
listen = "127.0.0.1:{ports.foxglove}"
limits = {LIMITS}
"""


class Show:
    """Every built-in node in one ``sonibus run``, its sinks read back, a fuzzer session.

    Use as a context manager; ``close()`` ends everything it started."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.ports = Ports()
        self.recording = tmp / "show.mcap"
        self.config = tmp / "show.toml"
        self.jack_name = f"fuzz-{uuid.uuid4().hex[:8]}"
        self.children: list[Child] = []
        self.jackd: Child | None = None
        self.run: Child | None = None
        self.session: Any = None
        self.midi: MidiReader | None = None
        self.rss: Rss | None = None
        self.exit_code: int | None = None
        self._env_before = {k: os.environ.get(k) for k in ("JACK_DEFAULT_SERVER", "JACK_NO_START_SERVER")}

    # -- starting ---------------------------------------------------------------------

    def __enter__(self) -> Show:
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _start(self) -> None:
        os.environ["JACK_DEFAULT_SERVER"] = self.jack_name
        os.environ["JACK_NO_START_SERVER"] = "1"
        self.jackd = jackd = self._child(["jackd", "--no-realtime", "-n", self.jack_name, "-d", "dummy", "-r", "48000",
                             "-p", "256"])
        until(lambda: not jackd.alive or _jack_up(), 10, f"jackd -n {self.jack_name}", 0.1)
        if not jackd.alive:
            raise ShowError(f"jackd ended at start: {jackd.tail()}")
        self.plain = OscDump(self.ports.plain)
        self.children.append(self.plain)
        self.bundle = OscDump(self.ports.bundle)
        self.children.append(self.bundle)
        self.config.write_text(show_toml(self.ports, self.recording))
        self.run = self._child([SONIBUS, "-v", "run", str(self.config)])
        run = self.run
        until(lambda: not run.alive or any("sonibus: running" in text for _, text in run.out), 30,
              "sonibus run to start every node", 0.05)
        if not run.alive:
            raise ShowError(f"sonibus run ended at start: {run.tail(30)}")
        self.rss = Rss(run.pid)
        self.session = open_session(BusConfig(mode="peer", connect=(self.ports.endpoint,), multicast=False))
        until(lambda: self.session.info.peers_zid() or self.session.info.routers_zid(), 10, "the fuzzer's link")
        until(lambda: _has_port("midi:"), 10, "the midi node's JACK port", 0.05)
        self.midi = MidiReader("midi:")

    def _child(self, args: list[str]) -> Child:
        child = Child(args, env=dict(os.environ))
        self.children.append(child)
        return child

    # -- watching -----------------------------------------------------------------------

    @property
    def alive(self) -> bool:
        return self.run is not None and self.run.alive

    def nodes(self, timeout: float = 3.0) -> dict[str, str]:
        """Each node's state as it reports it on its node key (``sonibus/nodes/**``)."""
        states = {}
        for reply in self.session.get("sonibus/nodes/**", timeout=timeout):
            if reply.ok is None:
                continue
            try:
                about = msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
                states[str(about["node"])] = str(about.get("state"))
            except (ValueError, KeyError, TypeError, msgpack.ExtraData):
                states[str(reply.ok.key_expr)] = "undecodable"
        return states

    def log(self, since: float = 0.0) -> list[str]:
        """What ``sonibus run`` wrote on stderr (its log) since ``since``."""
        return [text for read, text in (self.run.err if self.run else []) if read >= since]

    def console(self, since: float = 0.0) -> list[str]:
        return [text for read, text in (self.run.out if self.run else []) if read >= since]

    def stop_run(self, timeout: float = 20.0) -> int | None:
        """SIGINT to ``sonibus run``; its exit code (``None``: it had to be killed)."""
        if self.run is not None and self.exit_code is None:
            self.exit_code = self.run.stop(signal.SIGINT, timeout)
        return self.exit_code

    # -- ending ----------------------------------------------------------------------------

    def close(self) -> None:
        if self.midi is not None:
            with contextlib.suppress(Exception):
                self.midi.close()
            self.midi = None
        if self.session is not None:
            with contextlib.suppress(Exception):
                self.session.close()
            self.session = None
        if self.run is not None and self.exit_code is None and self.run.alive:
            self.exit_code = self.run.stop(signal.SIGINT, 10.0)
        if self.run is not None:  # the log, for a report
            (self.tmp / "run.log").write_text("\n".join(self.log()) + "\n")
        if self.rss is not None:
            self.rss.close()
        for child in reversed(self.children):
            if child is self.jackd:  # a killed jackd keeps its slot in JACK's registry (8 servers at most)
                child.stop(signal.SIGINT, 5.0)
            child.kill()
        for leftover in Path("/dev/shm").glob(f"jack_sem.*_{self.jack_name}_*"):
            leftover.unlink(missing_ok=True)
        for key, value in self._env_before.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def _jack_up() -> bool:
    try:
        probe = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "fuzz-probe")
    except rtmidi.SystemError:
        return False
    probe.delete()
    return True


def _has_port(name: str) -> bool:
    try:
        probe = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, "fuzz-probe")
    except rtmidi.SystemError:
        return False
    try:
        return any(name in p for p in probe.get_ports())
    finally:
        probe.delete()
