"""Opening a JACK client, connecting its ports and closing it, with one-line errors.

libjack prints its own complaints on stderr ("Cannot connect to server
socket ..."); they go to this module's debug log instead, so a missing server
is the one line ``open_client`` raises.
"""

from __future__ import annotations

import logging
import os
import threading
import time

import jack

from sonibus.bus.errors import ConfigError, SonibusError

log = logging.getLogger(__name__)


class ServerGone(SonibusError):
    """The JACK server a client was on stopped (or threw it out)."""


jack.set_error_function(lambda text: log.debug("libjack: %s", text))
jack.set_info_function(lambda text: log.debug("libjack: %s", text))


def server_name(server: str) -> str:
    """The JACK server a client of ``server`` reaches ("" is the default one)."""
    return server or os.environ.get("JACK_DEFAULT_SERVER", "default")


OPEN_TIMEOUT_S = 5.0  # a JACK server that does not answer (jackd stopped with Ctrl-Z, or hung): one line, not a hang


def open_client(name: str, server: str, key: str = "server") -> jack.Client:
    """A client of JACK server ``server`` (never starting one); ``ConfigError`` naming
    ``key`` (the node's option that chose JACK) when it is not running, or does not answer within ``OPEN_TIMEOUT_S``
    (libjack waits for it without a bound: a client it opens too late is closed)."""
    opened: list[jack.Client] = []
    failed: list[Exception] = []
    late = threading.Lock()  # the caller gave up (held) or took the client: never both

    def open_() -> None:
        try:
            client = jack.Client(name, no_start_server=True, servername=server or None)
        except Exception as exc:  # (raised again by the caller's thread)
            failed.append(exc)
            return
        with late:
            if given_up:
                client.close()
            else:
                opened.append(client)

    given_up = False
    opening = threading.Thread(target=open_, name=f"jack-open-{name}", daemon=True)
    opening.start()
    opening.join(OPEN_TIMEOUT_S)
    with late:
        if opened:
            return opened[0]
        if opening.is_alive():
            given_up = True
            raise ConfigError(f"key '{key}': JACK server '{server_name(server)}' does not answer within "
                              f"{OPEN_TIMEOUT_S:g} s — is jackd stopped (Ctrl-Z in its terminal: 'fg') or hung?")
    exc = failed[0]
    if not isinstance(exc, jack.JackOpenError):
        raise exc
    jackd = f"jackd -n {server}" if server else "jackd"
    log.debug("jack.Client(%r, servername=%r): %s", name, server, exc)
    raise ConfigError(f"key '{key}': no JACK server '{server_name(server)}' running — start one first, "
                      f"e.g. '{jackd} -d dummy -r 48000' (no sound card) or '{jackd} -d alsa'") from None


def connect(client: jack.Client, ours: list[jack.OwnPort], theirs: tuple[str, ...], key: str) -> None:
    """Connect each of ``ours`` to the port of ``theirs`` in the same place (ours an
    input: theirs plays into it); ``ConfigError`` naming ``key`` and the ports there
    are when one cannot be connected."""
    for port, other in zip(ours, theirs, strict=False):
        try:
            if port.is_input:
                client.connect(other, port)
            else:
                client.connect(port, other)
        except jack.JackError as exc:
            there = client.get_ports(is_audio=True, is_input=port.is_output, is_output=port.is_input)
            names = ", ".join(repr(p.name) for p in there if not p.name.startswith(client.name + ":")) or "none"
            raise ConfigError(f"key '{key}': cannot connect '{port.name}' with '{other}' ({exc}) — "
                              f"audio {'outputs' if port.is_input else 'inputs'} there: {names}") from None


class ProcessEnd:
    """The way a Python process callback's thread ends before its client is closed.

    jack2 cancels a client's process thread when it deactivates it (``JackClient::Deactivate``:
    ``fThread.Kill()``, a ``pthread_cancel``), assuming it waits in libjack by then. A thread
    still running Python (a late cycle on a busy machine) is cancelled holding the GIL, and
    every thread of the process waits for it for ever: a test's stop of the bridge hung a
    whole suite that way. So the callback calls ``check()`` first thing; ``end()`` makes its
    next cycle raise ``jack.CallbackExit``, which JACK answers by ending the thread itself, in
    C, out of Python; ``end`` waits (bounded) for that thread to be gone before the client closes.
    """

    def __init__(self) -> None:
        self.asked = False
        self.tid: int | None = None  # the process thread's (its first cycle's)

    def check(self) -> None:
        """Raise ``jack.CallbackExit`` once ``end`` was asked (JACK's process thread, before any work)."""
        if self.tid is None:
            self.tid = threading.get_native_id()
        if self.asked:
            raise jack.CallbackExit

    def end(self, timeout: float) -> bool:
        """Ask the process thread to end and wait up to ``timeout`` s for it to be gone (True if it is,
        or never ran a cycle; a hung server runs none: the close that follows is bounded too)."""
        self.asked = True
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            tid = self.tid
            if tid is not None and not os.path.exists(f"/proc/self/task/{tid}"):
                return True
            time.sleep(0.002)
        return self.tid is None


def close_client(client: jack.Client, timeout: float, ending: ProcessEnd | None = None) -> bool:
    """Deactivate and close ``client`` (its ports go with it); False if its server did
    not answer within ``timeout`` s (a stopped or hung jackd: libjack waits for it
    without a bound, so the closing is left to a daemon thread that ends when it does);
    ``ending``: the client's process callback's, whose thread ends first (``ProcessEnd``)."""
    started = time.monotonic()
    if ending is not None:
        ending.end(timeout / 2)
    failed: list[BaseException] = []

    def close() -> None:
        try:
            client.deactivate()
            client.close()
        except Exception as exc:  # (raised again below, by the caller's thread)
            failed.append(exc)

    closing = threading.Thread(target=close, name=f"jack-close-{client.name}", daemon=True)
    closing.start()
    closing.join(max(0.1, timeout - (time.monotonic() - started)))
    if failed:
        raise failed[0]
    return not closing.is_alive()
