"""A private JACK server per test (dummy driver: no sound card), shared by the
MIDI and audio tests: their conftests import the ``jack`` fixture from here."""

from __future__ import annotations

import contextlib
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jack as jack_client
import pytest

from .conftest import Network, Process, require_tool, wait_for

RATE = 48000
PERIOD = 256

jack_client.set_error_function(lambda text: None)  # libjack's "cannot connect" while the server starts
jack_client.set_info_function(lambda text: None)


def jack_up(name: str) -> bool:
    """Whether JACK server ``name`` takes clients."""
    try:
        probe = jack_client.Client("probe", no_start_server=True, servername=name)
    except jack_client.JackOpenError:
        return False
    probe.close()
    return True


@contextlib.contextmanager
def running(spawn: Any, monkeypatch: pytest.MonkeyPatch, net: Network) -> Iterator[tuple[str, Process]]:
    """A JACK server of a name of its own, made the default: its name and its process; always stopped,
    after the test's nodes (``net``): JACK clients end before their server, as in a show. (Stopped
    first, a server was once left waiting on a client of the test's process and did not end.)"""
    jackd = require_tool("jackd", "jackd2")
    name = f"sonibus-{uuid.uuid4().hex[:8]}"
    monkeypatch.setenv("JACK_DEFAULT_SERVER", name)
    monkeypatch.setenv("JACK_NO_START_SERVER", "1")
    server: Process = spawn(jackd, "--no-realtime", "-n", name, "-d", "dummy", "-r", str(RATE), "-p", str(PERIOD))
    try:
        wait_for(lambda: server.popen.poll() is not None or jack_up(name), timeout=10, what=f"jackd -n {name}")
        if server.popen.poll() is not None:
            _, err = server.popen.communicate()
            pytest.fail(f"jackd -n {name} ended at start: {err[-500:]}")
        yield name, server
    finally:
        net.close()
        server.stop(timeout=5)
        for leftover in Path("/dev/shm").glob(f"jack_sem.*_{name}_*"):  # jackd 1.9 leaves its clients' semaphores
            leftover.unlink(missing_ok=True)


@pytest.fixture
def jack(spawn, monkeypatch, net) -> Iterator[str]:
    """The name of a running JACK server, made the default for this test; always stopped."""
    with running(spawn, monkeypatch, net) as (name, _):
        yield name


@pytest.fixture
def jack_server(spawn, monkeypatch, net) -> Iterator[tuple[str, Process]]:
    """Instead of ``jack``, for a test that stops the server itself: its name and its process."""
    with running(spawn, monkeypatch, net) as server:
        yield server


class MidiInput:
    """A JACK MIDI input of the test's own (python-rtmidi), connected to the first port whose
    name holds ``connect``, or a virtual port ``virtual``; ``messages`` is what came so far.

    Polled, never a Python callback: rtmidi's JACK thread calling into Python needs the GIL,
    and closing a JACK client waits for that thread's cycle while holding it. A suite's
    worker once hung for good there (``jack_client_close`` in ``delete``, the callback's
    thread waiting on the GIL), where no alarm or watchdog thread could reach it."""

    def __init__(self, client: str, connect: str = "", virtual: str = "") -> None:
        import rtmidi

        self.port = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, client, queue_size_limit=65536)
        self._messages: list[list[int]] = []
        if virtual:
            self.port.open_virtual_port(virtual)
        else:
            names = self.port.get_ports()
            wanted = [i for i, n in enumerate(names) if connect.lower() in n.lower()]
            if not wanted:
                self.port.delete()
                raise AssertionError(f"no port '{connect}' among {names}")
            self.port.open_port(wanted[0], "in")

    @property
    def messages(self) -> list[list[int]]:
        """Every message so far, oldest first (what rtmidi's queue holds taken in now)."""
        while (got := self.port.get_message()) is not None:
            self._messages.append(got[0])
        return self._messages

    def close(self) -> None:
        self.port.close_port()
        self.port.delete()
