"""OSC sink: every sample of a key expression as one OSC message over UDP."""

from __future__ import annotations

import logging
import socket
import string
import time
from dataclasses import dataclass

from pythonosc.osc_message_builder import OscMessageBuilder

from sonibus.bus import codec, keys
from sonibus.bus.adapter import Adapter
from sonibus.bus.errors import ConfigError
from sonibus.bus.keys import Key
from sonibus.bus.options import bad

log = logging.getLogger(__name__)

FIELDS = ("robot", "section", "joint", "name", "key")
WARN_EVERY_S = 10.0


@dataclass(frozen=True)
class OscSinkConfig:
    """Options of the ``osc`` adapter."""

    subscribe: str = "*/joints/*"                # key expression to forward
    targets: tuple[str, ...] = ("127.0.0.1:9000",)  # host:port of each receiver
    address: str = "/{robot}/joints/{joint}"     # OSC address template: {robot} {joint} {section} {name} {key}
    queue: int = 4096                            # samples buffered before the oldest are dropped

    def __post_init__(self) -> None:
        try:
            keys.expr(self.subscribe)
        except ConfigError as exc:
            raise bad("subscribe", str(exc)) from None
        if not self.targets:
            raise bad("targets", "targets is empty — give at least one host:port")
        for target in self.targets:
            try:
                parse_target(target)
            except ConfigError as exc:
                raise bad("targets", str(exc)) from None
        used = {f for _, f, _, _ in string.Formatter().parse(self.address) if f is not None}
        unknown = used - set(FIELDS)
        if unknown:
            raise bad("address", f"'{self.address}' uses unknown field '{{{sorted(unknown)[0]}}}' — "
                      f"fields: {', '.join('{' + f + '}' for f in FIELDS)}")
        if not self.address.startswith("/"):
            raise bad("address", f"'{self.address}' must start with '/'")


def parse_target(target: str) -> tuple[str, int]:
    """``"host:port"`` → ``(host, port)``, or ``ConfigError``."""
    host, sep, port = target.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"target '{target}' is not host:port with a port in 1..65535")
    return host, int(port)


class OscSink(Adapter):
    """Forwards bus samples to OSC receivers (Pure Data, Max, SuperCollider) over UDP."""

    Config = OscSinkConfig

    def _start(self) -> None:
        cfg: OscSinkConfig = self.config
        self.sent = self.skipped = 0
        self._last_warning = 0.0
        self._addresses: dict[str, str] = {}
        self._targets = [_resolve(*parse_target(t)) for t in cfg.targets]
        self._socket = self.own(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
        subscriber, self._queue = self.bus.subscribe(cfg.subscribe, cfg.queue)
        self.own(subscriber)
        self.own(self._queue)
        self.spawn(self._forward, "forward")

    @property
    def dropped(self) -> int:
        return self._queue.dropped

    def _forward(self) -> None:
        while not self.stopping.is_set():
            item = self._queue.get(timeout=0.2)
            if item is not None:
                self._send(*item)

    def _send(self, key: str, payload: bytes) -> None:
        try:
            address = self._addresses.get(key) or self._address(key)
            value = codec.decode(payload)["v"]
            builder = OscMessageBuilder(address)
            builder.add_arg(float(value), OscMessageBuilder.ARG_TYPE_FLOAT)
            datagram = builder.build().dgram
            for target in self._targets:
                self._socket.sendto(datagram, target)
            self.sent += 1
        except (ValueError, KeyError, TypeError, OSError) as exc:
            self.skipped += 1
            self._warn(f"sample on '{key}' not sent: {type(exc).__name__}: {exc}")

    def _address(self, key: str) -> str:
        parsed = Key.parse(key)
        address = self.config.address.format(robot=parsed.robot, section=parsed.section, joint=parsed.name,
                                             name=parsed.name, key=key)
        self._addresses[key] = address
        return address

    def _warn(self, message: str) -> None:
        now = time.monotonic()
        if now - self._last_warning >= WARN_EVERY_S:
            self._last_warning = now
            log.warning("%s: %s (%d skipped so far)", self.name, message, self.skipped)


def _resolve(host: str, port: int) -> tuple[str, int]:
    try:
        return socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)[0][4][:2]
    except socket.gaierror as exc:
        raise ConfigError(f"target '{host}:{port}': cannot resolve '{host}': {exc.strerror}") from None
