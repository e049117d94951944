"""The JACK MIDI input of ``midi-in`` (``api = "jack"``) through JACK-Client, not python-rtmidi.

python-rtmidi's JACK input segfaulted in its callback thread (``_rtmidi``, issue 33):
a native crash there ends the whole ``sonibus run``. Here libjack calls our process
callback once a period on its real-time thread; it copies each channel message of
the period into the node's bounded queue (full: the oldest go, counted ``dropped``)
and does nothing else. JACK's notification thread only wakes the ``watch`` worker,
which says when a controller connects or leaves, connects again to a new port that
matches ``connect``, and fails the node loudly when the JACK server goes away.

Measured against rtmidi's JACK input in the same run (``bench/midi_in_latency.py``):
see docs/midi.md.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import jack

from sonibus.adapters.jack import client as jack_client
from sonibus.bus.errors import ConfigError

from .ports import find_port

log = logging.getLogger(__name__)

CLOSE_TIMEOUT_S = 2.0


class JackMidiIn:
    """A JACK client named ``client_name`` with one MIDI input port ``port``, connected
    to the output port matching ``connect`` (if given: again whenever one appears and
    none is connected). ``receive(message)`` gets the bytes of each channel message
    (status 0x80..0xEF; system messages, sysex and clock are left out, as rtmidi's
    ``ignore_types`` did) on JACK's real-time thread: it must only enqueue."""

    def __init__(self, client_name: str, port: str, connect: str, receive: Callable[[bytes], None]) -> None:
        self.wanted = connect
        self._receive = receive
        self.failure: BaseException | None = None   # set by JACK's threads, raised by ``watch``
        self.changed = threading.Event()             # a port came, went, or was (dis)connected
        self.connected: frozenset[str] = frozenset()
        # what JACK told of our port's connections and its list did not show yet: the other port's
        # name ("" if it was gone before its name could be read) -> connected; ``unshown`` says if any
        self._told: dict[str, bool] = {}
        self._told_lock = threading.Lock()
        self.heard = 0                               # channel messages handed to ``receive``
        self._ending = jack_client.ProcessEnd()
        self.client = jack_client.open_client(client_name, "", key="api")
        try:
            self.port = self.client.midi_inports.register(port)
            self._ours = str(self.port.name)
            self.client.set_process_callback(self._process)
            self.client.set_shutdown_callback(self._gone)
            self.client.set_port_connect_callback(self._connect_told, only_available=False)
            self.client.set_port_registration_callback(lambda p, on: self.changed.set(), only_available=False)
            self.client.activate()
            if connect and not self.link():
                names = [p.name for p in self.client.get_ports(is_midi=True, is_output=True)]
                raise ConfigError(f"key 'connect': no MIDI output port matches '{connect}' (api jack) — "
                                  f"available: {', '.join(repr(n) for n in names) or 'none'}")
        except BaseException:
            self.close()
            raise

    @property
    def name(self) -> str:
        """Our port's full name (``surface-in:sonibus-in``)."""
        return str(self.port.name)

    # -- JACK's threads ---------------------------------------------------------------

    def _process(self, frames: int) -> None:
        self._ending.check()  # (first, out of the try: its CallbackExit is a close, not a failure)
        try:
            for _, data in self.port.incoming_midi_events():
                message = bytes(data)  # (a view of JACK's buffer, valid in this period only)
                if len(message) > 1 and 0x80 <= message[0] < 0xF0:
                    self.heard += 1
                    self._receive(message)
        except Exception as exc:  # JACK stops calling after an exception: ``watch`` fails the node with it
            self.failure = exc
            self.changed.set()
            raise jack.CallbackExit from None

    def _connect_told(self, a: jack.Port | None, b: jack.Port | None, on: bool) -> None:
        names = (a.name if a is not None else "", b.name if b is not None else "")
        if self._ours in names:
            with self._told_lock:
                self._told[names[1] if names[0] == self._ours else names[0]] = on
        self.changed.set()

    def _gone(self, status: jack.Status, reason: str) -> None:
        self.failure = jack_client.ServerGone(f"JACK server '{jack_client.server_name('')}' went away "
                                              f"or dropped client '{self.client.name}': {reason}")
        self.changed.set()

    # -- the watch worker -------------------------------------------------------------

    def link(self) -> bool:
        """Connect to the first output port matching ``connect`` (True if one did)."""
        try:
            names = [p.name for p in self.client.get_ports(is_midi=True, is_output=True)
                     if not p.name.startswith(self.client.name + ":")]
        except jack.JackError as exc:  # a port went while JACK listed them (python-jack looks each name up)
            log.debug("listing ports for %s: %s", self.name, exc)
            self.changed.set()  # (look again at once)
            return False
        index = find_port(names, self.wanted)
        if index is None:
            return False
        try:
            self.client.connect(names[index], self.port)
        except jack.JackError as exc:  # it went between the listing and the connecting: the next change retries
            log.debug("connecting %s to %s: %s", names[index], self.name, exc)
            return False
        return True

    def changes(self) -> tuple[set[str], set[str]]:
        """The ports that connected to ours and those that left since the last call; raises
        what JACK's threads met (the server gone). Reconnects to ``connect`` when alone."""
        if self.failure is not None:
            raise self.failure
        self.changed.clear()
        try:
            now = frozenset(p.name for p in self.port.connections)
            if self.wanted and not now and self.link():
                now = frozenset(p.name for p in self.port.connections)
        except jack.JackError as exc:  # a port went while JACK listed the connections: look again at once
            log.debug("listing %s's connections: %s", self.name, exc)
            self.changed.set()
            return set(), set()
        came, left = set(now - self.connected), set(self.connected - now)
        self.connected = now
        with self._told_lock:  # (what shows now was told: "" is any port that left)
            for peer, on in list(self._told.items()):
                if ((peer in now) == on) if peer else (left or not now):
                    del self._told[peer]
        return came, left

    @property
    def unshown(self) -> bool:
        """Whether JACK told of a connection or disconnection of our port that its list does not show yet."""
        return bool(self._told)

    def forget_told(self) -> list[str]:
        """Stop waiting for what was told and never showed; the ports it named."""
        with self._told_lock:
            peers, self._told = sorted(self._told), {}
        return peers

    def close(self) -> None:
        """Close the client (its port goes with it); bounded if the server hangs. Safe twice."""
        client, self.client = getattr(self, "client", None), None
        if client is not None and not jack_client.close_client(client, CLOSE_TIMEOUT_S, self._ending):
            log.warning("JACK server '%s' did not answer within %g s: client '%s' stays until it does",
                        jack_client.server_name(""), CLOSE_TIMEOUT_S, client.name)
