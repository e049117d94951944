"""Opening a JACK client, connecting its ports and closing it, with one-line errors.

libjack prints its own complaints on stderr ("Cannot connect to server
socket ..."); they go to this module's debug log instead, so a missing server
is the one line ``open_client`` raises.
"""

from __future__ import annotations

import logging
import os
import threading

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


def close_client(client: jack.Client, timeout: float) -> bool:
    """Deactivate and close ``client`` (its ports go with it); False if its server did
    not answer within ``timeout`` s (a stopped or hung jackd: libjack waits for it
    without a bound, so the closing is left to a daemon thread that ends when it does)."""
    failed: list[BaseException] = []

    def close() -> None:
        try:
            client.deactivate()
            client.close()
        except Exception as exc:  # (raised again below, by the caller's thread)
            failed.append(exc)

    closing = threading.Thread(target=close, name=f"jack-close-{client.name}", daemon=True)
    closing.start()
    closing.join(timeout)
    if failed:
        raise failed[0]
    return not closing.is_alive()
