"""Shared fixtures: real Zenoh sessions on loopback standing for machines, a
simulated robot, external tools that must exist, and waiting on conditions."""

from __future__ import annotations

import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from sonibus.adapters.sim import SimConfig, SimRobot
from sonibus.bus import Bus, BusConfig, open_session
from sonibus.bus.control import open_control

from . import turns
from .supervisor import Supervisor
from .watchdog import pytest_runtest_protocol, pytest_unconfigure  # noqa: F401 - hooks, found by name


def pytest_configure(config: pytest.Config) -> None:
    config.pluginmanager.register(turns, "sonibus-turns")  # (its hook has the watchdog's name)

SONIBUS = str(Path(sys.executable).with_name("sonibus"))

# Nothing the tests start scouts this machine's own network by multicast (only the network
# namespaces they make): tests/nomulticast/sitecustomize.py guards every Python process they
# start, and this one.
NO_MULTICAST = Path(__file__).resolve().parent / "nomulticast"
os.environ.setdefault("SONIBUS_TEST_NETNS", os.readlink("/proc/self/ns/net"))
# every Python child says where each of its threads is when it dies of a signal: a child that does
# not end when asked is sent SIGABRT and its stacks are in the failure (``Process.stop``)
os.environ.setdefault("PYTHONFAULTHANDLER", "1")
os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(NO_MULTICAST), os.environ.get("PYTHONPATH")) if p)
_guard = importlib.util.spec_from_file_location("sonibus_no_multicast", NO_MULTICAST / "sitecustomize.py")
assert _guard is not None and _guard.loader is not None
_guarding = importlib.util.module_from_spec(_guard)
_guard.loader.exec_module(_guarding)
_guarding.guard(zenoh)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(predicate: Callable[[], Any], timeout: float = 5.0, what: str = "condition",
             explain: Callable[[], str] | None = None) -> Any:
    """Poll ``predicate`` until it returns something truthy; fail after ``timeout``
    (with ``explain()`` in the message, if given)."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what}" + (f"\n{explain()}" if explain else ""))
        time.sleep(0.01)


def queued_keys(queue: Any) -> list[str]:
    """The keys of what is put into ``queue`` (a node's ``SampleQueue``) from now on, as they
    come: a sink that takes frames where they arrive (``Streams(direct=...)``) queues none."""
    keys_: list[str] = []
    put = queue.put

    def spy(item: Any, *args: Any, **kwargs: Any) -> Any:
        keys_.append(item[0])
        return put(item, *args, **kwargs)

    queue.put = spy
    return keys_


def require_tool(name: str, package: str) -> str:
    """The path of an external tool; a missing tool fails the test (never skips)."""
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"'{name}' is not installed: apt-get install {package} (.ci/run does)")
    return path


class Network:
    """Sessions on one loopback 'network': the first listens, the others connect.
    Each session stands for a machine. Multicast is off, so tests do not mix."""

    def __init__(self) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self._sessions: list[Any] = []
        self._adapters: list[Any] = []

    def config(self, **changes: Any) -> BusConfig:
        role = {"connect": (self.endpoint,)} if self._sessions else {"listen": (self.endpoint,)}
        return BusConfig(multicast=False, **{**role, **changes})

    def bus(self, node: str = "test", control: bool = False) -> Bus:
        """A session on this network; with ``control``, its control session too (``bus/control.py``,
        as every ``sonibus run``: not by default, as a second session costs each test up to 0.5 s,
        Zenoh's wait for the peers its gossip names)."""
        config = self.config()
        session = open_session(config)
        self._sessions.append(session)
        urgent = open_control(config, session) if control else None
        if urgent is not None:
            self._sessions.append(urgent)
        bus = Bus(session, node=node, control=urgent)
        if len(self._sessions) > 1:
            wait_for(lambda: session.info.peers_zid() or session.info.routers_zid(), what="peer connection")
        return bus

    def cli_args(self) -> list[str]:
        """Bus options that join a CLI process to this network."""
        if not self._sessions:
            self.bus("anchor")
        return ["--no-multicast", "--connect", self.endpoint]

    def start(self, adapter: Any, bus: Bus | None = None) -> Any:
        adapter.start(bus or self.bus(adapter.name))
        self._adapters.append(adapter)
        return adapter

    def sim(self, robot: str = "pepper", bus: Bus | None = None, **options: Any) -> SimRobot:
        return self.start(SimRobot(SimConfig(robot=robot, **options), name=f"sim-{robot}"), bus)

    def close(self) -> None:
        """Stop the nodes started here and close the sessions, newest first; safe twice."""
        while self._adapters:
            self._adapters.pop().stop()
        while self._sessions:
            self._sessions.pop().close()


@pytest.fixture
def net() -> Iterator[Network]:
    network = Network()
    try:
        yield network
    finally:
        network.close()


class Process:
    """A child process that is always ended, also when the test fails.

    With ``collect=True`` its stdout lines (and stderr's, with ``merge=True``) are
    gathered in ``lines`` as they come."""

    def __init__(self, args: list[str], collect: bool = False, merge: bool = False, **kwargs: Any) -> None:
        kwargs.setdefault("stdin", subprocess.DEVNULL)  # (not the runner's terminal: `run` takes that as by hand)
        self.popen = subprocess.Popen(args, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT if merge else subprocess.PIPE, text=True,
                                      start_new_session=True, **kwargs)
        self.lines: list[str] = []
        if collect:
            threading.Thread(target=self._collect, daemon=True).start()

    def _collect(self) -> None:
        try:
            for line in self.popen.stdout:
                self.lines.append(line.rstrip("\n"))
        except ValueError:  # (stop's communicate closed the pipe under it: the rest is in what it returns)
            pass

    def stop(self, sig: int = signal.SIGINT, timeout: float = 5.0) -> tuple[int, str, str]:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
        try:
            out, err = self.popen.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{self.popen.args} did not end within {timeout} s of signal {sig}; "
                        f"where it was:\n{self.stacks()}")
        return self.popen.returncode, out, err

    def stacks(self) -> str:
        """End the process with SIGABRT (faulthandler, on in every child: every thread's stack
        on its stderr) and give back the end of what it printed, then kill what is left."""
        try:
            os.kill(self.popen.pid, signal.SIGABRT)
            out, err = self.popen.communicate(timeout=5)
        except (OSError, subprocess.TimeoutExpired, ValueError):
            out = err = ""
        finally:
            self.kill()
        return ((err or "") + (out or "") + "\n".join(self.lines[-100:]))[-6000:]

    def kill(self) -> None:
        """SIGKILL its process group; then read what is left, for a bounded time: a grandchild that
        left the group (a session of its own) can hold the pipes open for ever, and a teardown
        blocked on them would wait with no timeout left to end it."""
        if self.popen.poll() is not None:
            return
        os.killpg(self.popen.pid, signal.SIGKILL)
        try:
            self.popen.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            for pipe in (self.popen.stdout, self.popen.stderr):
                if pipe is not None:
                    pipe.close()
            self.popen.wait(timeout=10)


@pytest.fixture
def spawn() -> Iterator[Callable[..., Process]]:
    started: list[Process] = []

    def start(*args: str, **kwargs: Any) -> Process:
        process = Process(list(args), **kwargs)
        started.append(process)
        return process

    try:
        yield start
    finally:
        for process in started:
            process.kill()


@pytest.fixture
def supervisor() -> Iterator[Supervisor]:
    """systemd's side of sd_notify and the watchdog, listening on a socket of its own."""
    folder = tempfile.mkdtemp(prefix="sb-notify-")  # (a unix socket's path has at most 107 bytes)
    listening = Supervisor(Path(folder) / "notify")
    try:
        yield listening
    finally:
        listening.close()
        shutil.rmtree(folder, ignore_errors=True)


def run_cli(*args: str, timeout: float = 20.0) -> subprocess.CompletedProcess[str]:
    """Run ``sonibus ARGS`` to completion."""
    return subprocess.run([SONIBUS, *args], capture_output=True, text=True, timeout=timeout)


FIGURES: list[str] = []  # measured values, shown after the run (never asserted: these machines are noisy)


@pytest.fixture
def figure(request: pytest.FixtureRequest) -> Callable[..., None]:
    """``figure("loss detected", 1.62, "s")``: a measured value, shown in the summary."""
    def record(name: str, value: float, unit: str = "") -> None:
        shown = f"{value:.3f}" if isinstance(value, float) else str(value)
        # a test's user properties travel with its report, so figures measured in an xdist worker reach the summary
        line = f"{request.node.name}: {name}: {shown}{f' {unit}' if unit else ''}"
        request.node.user_properties.append(("figure", line))
    return record


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.when == "teardown":
        FIGURES.extend(value for name, value in report.user_properties if name == "figure")


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if FIGURES:
        terminalreporter.section("figures")
        for line in FIGURES:
            terminalreporter.write_line(line)
