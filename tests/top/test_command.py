"""The real ``sonibus top`` in a subprocess, on a terminal of its own (a pty): it
draws the show, and ``q`` ends it with 0, SIGINT or SIGTERM with 130, within 3 s;
without a terminal it says so in one line."""

from __future__ import annotations

import contextlib
import fcntl
import os
import pty
import signal
import struct
import subprocess
import termios
import threading
import time
from collections.abc import Callable, Iterator, Sequence

import pytest

from ..conftest import SONIBUS, free_port, run_cli, wait_for

EXIT_WITHIN_S = 3.0


class Terminal:
    """``sonibus top ARGS`` on a pty of 160x48, its screen output gathered; always ended.
    ``prefix`` runs it through another command (``ip netns exec NS``: in a network namespace)."""

    def __init__(self, *args: str, prefix: Sequence[str] = ()) -> None:
        self.master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 48, 160, 0, 0))
        # (faulthandler: a top that does not end is made to say where it is stuck, see ``ended_within``)
        env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": "160", "LINES": "48", "PYTHONFAULTHANDLER": "1"}
        self.process = subprocess.Popen([*prefix, SONIBUS, "top", *args], stdin=slave, stdout=slave, stderr=slave,
                                        env=env, start_new_session=True, close_fds=True)
        os.close(slave)
        self.output = bytearray()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:  # (also keeps the pty drained: a full one would block the app's drawing)
            try:
                data = os.read(self.master, 65536)
            except OSError:  # the child closed its side
                return
            if not data:
                return
            self.output += data

    def type(self, keys: bytes) -> None:
        os.write(self.master, keys)

    def ended_within(self, seconds: float) -> tuple[int, float]:
        """The exit status and how long it took from now; fails if it runs on."""
        started = time.monotonic()
        try:
            status = self.process.wait(timeout=seconds)
        except subprocess.TimeoutExpired:
            screen = self.tail()
            self.process.send_signal(signal.SIGABRT)  # faulthandler prints every thread's stack on the pty
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.process.wait(timeout=5)
            self._reader.join(2.0)
            stacks = bytes(self.output).rpartition(b"Fatal Python error")[2].decode(errors="replace")
            pytest.fail(f"sonibus top still runs {seconds} s later; its screen ended with {screen!r}; "
                        f"its threads were at: Fatal Python error{stacks}")
        return status, time.monotonic() - started

    def tail(self) -> bytes:
        return bytes(self.output[-600:])

    def close(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()
        self._reader.join(2.0)
        os.close(self.master)


@pytest.fixture
def terminal(net) -> Iterator[Callable[..., Terminal]]:
    opened: list[Terminal] = []

    def open_(*args: str) -> Terminal:
        opened.append(Terminal(*args, *net.cli_args()))
        return opened[-1]

    try:
        yield open_
    finally:
        for shown in opened:
            shown.close()


def drawn(screen: Terminal) -> bool:
    """Whether the screen shows the simulated robot in its table."""
    return b"frames/s" in screen.output and b"sim-pepper" in screen.output


@pytest.mark.parametrize(("end", "status"), [(b"q", 0), (signal.SIGINT, 130), (signal.SIGTERM, 130)],
                         ids=["q", "sigint", "sigterm"])
def test_top_in_a_terminal_draws_the_show_and_ends_within_3_s(net, terminal, figure, end, status):
    net.sim("pepper", rate_hz=20)
    screen = terminal()
    wait_for(lambda: drawn(screen), timeout=20, what="the robot on top's screen",
             explain=lambda: repr(screen.tail()))
    if isinstance(end, bytes):
        screen.type(end)
    else:
        screen.process.send_signal(end)
    code, took = screen.ended_within(EXIT_WITHIN_S)
    figure(f"exit after {end!r}", took, "s")
    assert code == status, screen.tail()
    assert b"Traceback" not in screen.output
    assert b"\x1b[?1049l" in screen.output  # the terminal's own screen given back (the alternate one left)


def test_top_reaching_nobody_says_whom_it_tried_and_what_to_check():
    """An empty show is not silent: a wrong --connect is named on the status line."""
    port = free_port()
    screen = Terminal("--no-multicast", "--connect", f"tcp/127.0.0.1:{port}")
    try:
        wait_for(lambda: b"reached no peer or router" in screen.output, timeout=20,
                 what="top's hint on its status line", explain=lambda: repr(screen.tail()))
        assert f"tcp/127.0.0.1:{port}".encode() in screen.output
        screen.type(b"q")
        assert screen.ended_within(EXIT_WITHIN_S)[0] == 0
    finally:
        screen.close()


def test_top_without_a_terminal_says_so_in_one_line():
    result = run_cli("top", "--no-multicast")
    assert result.returncode == 1
    (line,) = result.stderr.splitlines()
    assert line.startswith("sonibus: error: top draws on a terminal") and "sonibus nodes" in line


def test_a_bad_redraw_interval_is_a_usage_error_in_one_line():
    result = run_cli("top", "--every", "0", "--no-multicast")
    assert result.returncode == 2
    assert result.stderr == "sonibus: error: --every 0: give a redraw interval of 0.02 to 10 s, e.g. --every 0.25\n"
