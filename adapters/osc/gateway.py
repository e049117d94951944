"""OSC command gateway (adapter ``osc-gateway``): ``/<robot>/cmd/<verb> args...`` over
UDP (and TCP) becomes a command on the bus, ``/<robot>/program/<verb> args...`` a
request to the robot's show (``/pepper/program/scenario "story"``); the answer goes
back to the sender as ``/<robot>/reply/<verb> 1 "<result JSON>"`` or ``... 0 "<code>" "<message>"``.

Packets are read as strictly as liblo reads them (``wire.messages``): nothing in a
malformed packet runs, and each command in it is answered ``bad_request``.

The addresses taken are the table of ``routes`` (which OSCQuery serves too).

Queries are asynchronous (a Zenoh callback handler), so a slow or missing robot
never stalls the receive loop, and commands reach a robot in the order they came.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import json
import logging
import socket
import time
from dataclasses import dataclass
from typing import Any

from sonibus.bus.adapter import Adapter
from sonibus.bus.client import Outcome, ask, ask_program
from sonibus.bus.errors import CommandError, ConfigError
from sonibus.bus.options import bad
from sonibus.bus.queue import SampleQueue
from sonibus.bus.udpdrops import KernelDrops

from . import routes, tcp, wire
from .config import parse_target
from .tcp import Peer

log = logging.getLogger(__name__)

COUNTERS = ("received", "commands", "replies_ok", "replies_error", "malformed", "unknown_address",
            "refused_source", "bad_args", "busy", "replies_lost", "internal", "kernel_dropped")
POLL_S = 0.2          # the TCP listener's timeout: how soon stop() is noticed
DROPS_EVERY_S = 1.0   # how often the kernel's drops on the UDP socket are read (as the stats are sent)
UDP_BUFFER = 1 << 20  # bytes of receive buffer asked for


@dataclass(frozen=True)
class OscGatewayConfig:
    """Options of the ``osc-gateway`` adapter."""

    listen: str = "127.0.0.1:9001"    # UDP host:port ("0.0.0.0:9001": every interface; port 0: any free port)
    tcp: str = ""                     # also TCP host:port, SLIP or size-prefixed frames ("": no TCP)
    allow: tuple[str, ...] = ("127.0.0.0/8", "::1/128")  # networks commands are taken from
    reply: bool = True                # answer each command at /<robot>/reply/<verb>
    timeout: float = 5.0              # seconds a robot has to answer
    max_args: int = wire.MAX_ARGS     # more arguments in one message: bad_request
    max_pending: int = 256            # commands awaiting an answer; more are refused as busy

    def __post_init__(self) -> None:
        parse_endpoint("listen", self.listen)
        if self.tcp:
            parse_endpoint("tcp", self.tcp)
        self.networks()
        if not self.timeout > 0:
            raise bad("timeout", f"{self.timeout:g} s must be more than 0")
        if not 0 < self.max_args <= 1024:
            raise bad("max_args", f"{self.max_args} must be in 1..1024")
        if self.max_pending < 1:
            raise bad("max_pending", f"{self.max_pending} must be at least 1")

    def networks(self) -> list[ipaddress.IPv4Network | ipaddress.IPv6Network]:
        if not self.allow:
            raise bad("allow", "allow is empty — give networks such as \"192.168.1.0/24\" (\"0.0.0.0/0\": anyone)")
        try:
            return [ipaddress.ip_network(n, strict=False) for n in self.allow]
        except ValueError as exc:
            raise bad("allow", f"{exc} — give networks such as \"10.0.0.0/8\" or \"::1/128\"") from None


def parse_endpoint(key: str, value: str) -> tuple[str, int]:
    """``"host:port"`` (``"[::1]:9001"`` for IPv6; port 0: any) → ``(host, port)``, or
    ``ConfigError`` naming ``key``."""
    try:
        return parse_target(value, lowest_port=0)
    except ConfigError as exc:
        raise bad(key, str(exc)) from None


class OscGateway(Adapter):
    """Commands from OSC (TouchOSC, Pure Data, SuperCollider) to robots, answered by OSC."""

    Config = OscGatewayConfig
    counters = COUNTERS

    def __init__(self, config: OscGatewayConfig | None = None, *, name: str = "") -> None:
        super().__init__(config, name=name)
        self.udp_address: tuple[Any, ...] = ()
        self.tcp_address: tuple[Any, ...] = ()
        self._pending = 0  # commands awaiting an answer (guarded by the base class's lock)
        self._kernel_drops: KernelDrops | None = None  # (made with the UDP socket)

    def _start(self) -> None:
        cfg: OscGatewayConfig = self.config
        self._allow = cfg.networks()
        self._replies = self.own(SampleQueue(4096))
        self._udp = self.own(self._bind(socket.SOCK_DGRAM, "listen", cfg.listen))
        self.udp_address = self._udp.getsockname()
        self._kernel_drops = KernelDrops(self._udp)
        if cfg.tcp:
            self._tcp = self.own(self._bind(socket.SOCK_STREAM, "tcp", cfg.tcp))
            self.tcp_address = self._tcp.getsockname()
            self.spawn(self._serve_tcp, "tcp")
        self.when_stopping(self._wake_udp)
        self.when_stopping(self._replies.close)  # (its worker waits on it, not on stopping)
        self.spawn(self._receive_udp, "udp")
        self.spawn(self._send_replies, "reply")
        self.address = f"OSC commands on udp {cfg.listen}{f' and tcp {cfg.tcp}' if cfg.tcp else ''}"
        log.info("%s: %s", self.name, self.address)

    def _serve_tcp(self) -> None:
        tcp.serve(self._tcp, self.stopping, self._allowed, self._guarded, self._problem, self._refused, POLL_S)

    def _bind(self, kind: socket.SocketKind, key: str, value: str) -> socket.socket:
        host, port = parse_endpoint(key, value)
        try:
            family, _, _, _, address = socket.getaddrinfo(host, port, type=kind)[0]
        except socket.gaierror as exc:
            raise ConfigError(f"node '{self.name}': key '{key}': cannot resolve '{host}': {exc.strerror}") from None
        sock = socket.socket(family, kind)
        try:
            if kind == socket.SOCK_STREAM:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # restart while old links linger
            else:  # room for a burst (the kernel caps it at net.core.rmem_max)
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_BUFFER)
            sock.bind(address)
            if kind == socket.SOCK_STREAM:
                sock.listen(16)
        except OSError as exc:
            sock.close()
            why = ("is already in use — stop the program that uses it or choose another port"
                   if exc.errno == errno.EADDRINUSE else f"cannot be used: {exc.strerror}")
            raise ConfigError(f"node '{self.name}': key '{key}': {value} {why}") from None
        sock.settimeout(POLL_S)
        return sock

    # -- receiving ------------------------------------------------------------------

    def _receive_udp(self) -> None:
        """Datagrams as they come; the kernel's drops looked at every ``DROPS_EVERY_S`` while they
        come and once after the last (a flood's end): with none coming, it sleeps until one does,
        or the stop wakes it (``_wake_udp``)."""
        checked = time.monotonic()
        self._udp.settimeout(None)
        waiting = None  # the socket's timeout: DROPS_EVERY_S from a datagram to the look after the last
        while not self.stopping.is_set():
            if time.monotonic() - checked >= DROPS_EVERY_S:
                checked = time.monotonic()
                self._count_kernel_drops()
            try:
                data, source = self._udp.recvfrom(65535)
            except TimeoutError:  # none for DROPS_EVERY_S: the drops looked at, then asleep until one comes
                checked = time.monotonic()
                self._count_kernel_drops()
                self._udp.settimeout(waiting := None)
                continue
            except OSError as exc:
                self.warn("internal", f"UDP receive failed: {exc}")
                continue
            if source is None:  # (the stop's shutdown)
                continue
            if waiting is None:
                self._udp.settimeout(waiting := DROPS_EVERY_S)
            if self._allowed(source[0]):
                self._guarded(data, Peer(source))
            else:
                self.count("received")

    def _wake_udp(self) -> None:
        """Wake the UDP worker's receive at the stop: the socket shut for reading (an unbound
        UDP socket says ENOTCONN, and wakes its reader all the same)."""
        with contextlib.suppress(OSError):
            self._udp.shutdown(socket.SHUT_RD)

    def _count_kernel_drops(self) -> None:
        """What the kernel dropped since the last look (the receive buffer was full): counted
        ``kernel_dropped`` and ``dropped``, said like the other losses."""
        found = self._kernel_drops.new() if self._kernel_drops else 0
        if not found:
            return
        self.count("kernel_dropped", found)
        self.count("dropped", found)
        size = self._udp.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        self.warn("kernel_dropped", f"{found:,} datagrams lost in the kernel's receive buffer ({size:,} bytes, full): "
                                    f"they came faster than this gateway reads — send fewer, or raise "
                                    f"net.core.rmem_max for a larger buffer")

    def metrics(self) -> dict[str, Any]:
        if self._kernel_drops is None or self._kernel_drops.available:
            return {}
        return {"kernel_dropped": "unavailable on this system"}

    def _allowed(self, host: str) -> bool:
        ip = ipaddress.ip_address(host.split("%")[0])
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped:
            ip = ip.ipv4_mapped
        if any(ip in network for network in self._allow):
            return True
        self.count("refused_source")
        self.warn("refused_source", f"ignored OSC from {host}: not in allow = {list(self.config.allow)}")
        return False

    def _refused(self, message: str) -> None:
        self.count("busy")
        self.warn("busy", message)

    # -- from packets to commands -----------------------------------------------------

    def _guarded(self, packet: bytes, peer: Peer) -> None:
        self.count("received")
        try:
            self._packet(packet, peer)
        except Exception as exc:  # a bug must not end the receive loop
            self.count("internal")
            self.warn("internal", f"packet from {peer.address[0]} failed: {type(exc).__name__}: {exc}")
            log.debug("%s: packet %r failed", self.name, packet[:64], exc_info=True)

    def _packet(self, packet: bytes, peer: Peer) -> None:
        try:
            found = wire.messages(packet)
        except wire.WireError as exc:  # nothing in a malformed packet runs
            self._problem(exc, peer)
            return
        for dgram in found:
            try:
                address, args = wire.parse(dgram, self.config.max_args)
            except wire.WireError as exc:
                self._problem(exc, peer)
                continue
            self._command(address, args, peer)

    def _problem(self, error: wire.WireError, peer: Peer | None = None) -> None:
        """Answer each command address of a refused packet with ``bad_request``; count and warn."""
        targets = [t for t in map(command_target, error.addresses) if t]
        if error.kind == "malformed":
            self.count("malformed")
            source = f" from {peer.address[0]}" if peer else " on a TCP connection"
            self.warn("malformed", f"refused OSC {error.address[:80] or 'packet'}{source}: {error}")
            for robot, verb in targets:  # nothing in the packet ran
                if peer:
                    self._answer(robot, verb, peer, CommandError("bad_request", f"{verb}: malformed OSC: {error}"))
        elif targets and peer:  # well formed but too long: answer it
            self._command_failed(*targets[0], peer, CommandError("bad_request", f"{targets[0][1]}: {error}"))
        else:
            self.count("unknown_address")
            self.warn("unknown_address", f"ignored OSC {error.address[:80] or 'packet'}: {error}")

    def _command(self, address: str, args: list[Any], peer: Peer) -> None:
        found = routes.match(address)
        if found is None:
            self.count("unknown_address")
            self.warn("unknown_address", f"ignored OSC {address[:80]}: not /<robot>/cmd/<verb> or "
                                         "/<robot>/program/<verb>")
            return
        robot, verb = found.robot, found.sent
        try:
            request = found.request(args)
        except CommandError as exc:
            self._command_failed(robot, verb, peer, exc)
            return
        with self._lock:
            busy = self._pending >= self.config.max_pending
            self._pending += not busy
        self.count("busy" if busy else "commands")
        if busy:
            self._answer(robot, verb, peer, CommandError(
                "busy", f"{self._pending} commands are waiting for robots; try again when they are answered"))
            return

        def done(outcome: Outcome) -> None:
            with self._lock:
                self._pending -= 1
            self._answer(robot, verb, peer, outcome)

        if found.route.section == "program":  # a request to the robot's show (a scenario), said to come from OSC
            ask_program(self.bus, robot, found.route.verb, {"by": "osc", **request}, done, self.config.timeout)
        else:
            ask(self.bus, robot, found.route.verb, request, done, self.config.timeout)

    def _command_failed(self, robot: str, verb: str, peer: Peer, error: CommandError) -> None:
        self.count("bad_args")
        self.warn("bad_args", f"{robot} {verb} from {peer.address[0]}: {error}")
        self._answer(robot, verb, peer, error)

    # -- replies ---------------------------------------------------------------------------

    def _answer(self, robot: str, verb: str, peer: Peer, outcome: Outcome) -> None:
        """Count an outcome and queue its reply (called from Zenoh's threads too: only enqueues)."""
        ok = not isinstance(outcome, CommandError)
        self.count("replies_ok" if ok else "replies_error")
        if not self.config.reply:
            return
        if isinstance(outcome, CommandError):
            args: tuple[Any, ...] = (0, outcome.code, " ".join(outcome.message.split())[:1000])
        else:
            args = (1, json.dumps(outcome, separators=(",", ":"), ensure_ascii=False, default=str))
        self._replies.put((peer, f"/{robot}/reply/{verb}", args))

    def _send_replies(self) -> None:
        while not self.stopping.is_set():
            item = self._replies.get()
            if item is None:
                continue
            peer, address, args = item
            try:
                packet = wire.message(address, *args)
                if peer.connection is not None:
                    peer.connection.send(packet)
                else:
                    self._udp.sendto(packet, peer.address)
                self.count("sent")
            except Exception as exc:  # OSError, or python-osc's BuildError
                self.count("replies_lost")
                self.warn("replies_lost", f"reply {address} to {peer.address[0]} not sent: {exc}")



def command_target(address: str) -> tuple[str, str] | None:
    """``/<robot>/cmd/<verb...>`` → ``(robot, verb as sent)``; None for any other address."""
    found = routes.match(address)
    return (found.robot, found.sent) if found else None
