"""Options of the ``oscquery`` adapter.

    [nodes.oscquery]
    adapter = "oscquery"
    listen = "127.0.0.1:5678"      # HTTP and WebSocket (port 0: any free port)
    gateway = "127.0.0.1:9001"     # the osc-gateway's UDP port, told to clients in HOST_INFO

A host given by name ("localhost") is resolved once, here: HOST_INFO and mDNS carry
IP addresses.
"""

from __future__ import annotations

import ipaddress
import socket
from dataclasses import dataclass, field
from typing import Literal

from sonibus.adapters.osc.config import parse_target
from sonibus.adapters.osc.gateway import parse_endpoint
from sonibus.bus.errors import ConfigError
from sonibus.bus.options import bad
from sonibus.bus.web import Limits

MAX_NAME_BYTES = 63  # an mDNS instance name is one DNS label


@dataclass(frozen=True)
class OscQueryConfig:
    """Options of the ``oscquery`` adapter."""

    listen: str = "127.0.0.1:5678"             # host:port of HTTP and WebSocket ("0.0.0.0:5678": every interface)
    gateway: str = "127.0.0.1:9001"            # host:port of the osc-gateway that takes the commands
    name: str = "sonibus"                      # HOST_INFO NAME and the mDNS instance name
    values: Literal["raw", "normalized"] = "raw"  # normalized: joints and derived values 0..1, as the OSC sink's
    mdns: bool = True                          # advertise _oscjson._tcp and the gateway's _osc._udp
    interfaces: tuple[str, ...] = ()           # IPv4 addresses mDNS binds to and advertises (default: the listen host)
    queue: int = 4096                          # samples waiting to be taken; past this the oldest are dropped
    limits: Limits = field(default_factory=Limits)  # [nodes.<name>.limits]: connections, clients, timeout_s
    # ``listen`` and ``gateway`` as (IP address, port), their names resolved
    listen_address: tuple[str, int] = field(init=False, repr=False, compare=False)
    gateway_address: tuple[str, int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        host, port = parse_endpoint("listen", self.listen)
        object.__setattr__(self, "listen_address", (_resolve("listen", host, self.listen), port))
        try:
            host, port = parse_target(self.gateway)  # (a port clients can send to: not 0)
        except ConfigError as exc:
            raise bad("gateway", f"{exc} — the osc-gateway's listen address") from None
        object.__setattr__(self, "gateway_address", (_resolve("gateway", host, self.gateway), port))
        if not self.name.strip() or "." in self.name:
            raise bad("name", f"{self.name!r} must be a non-empty name without '.' (an mDNS instance name)")
        if len(self.name.encode()) > MAX_NAME_BYTES:
            raise bad("name", f"{self.name[:20]!r}... is {len(self.name.encode())} bytes (UTF-8): an mDNS instance "
                              f"name has at most {MAX_NAME_BYTES} — give a shorter one")
        for address in self.interfaces:
            if _version(address) != 4:
                raise bad("interfaces", f"{address!r} is not an IPv4 address (mDNS is advertised on IPv4 only) — "
                                        "give addresses of this machine such as \"192.168.1.20\"")
        advertised = [("gateway", self.gateway_address[0])] + ([] if self.interfaces else [("listen", self.host)])
        for key, host in advertised if self.mdns else ():
            if _version(host) == 6 and not ipaddress.ip_address(host).is_unspecified:
                raise bad(key, f"{host} is IPv6, but mDNS is advertised on IPv4 only — give an IPv4 address"
                               f"{'' if key == 'gateway' else ', IPv4 interfaces'} or mdns = false")
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")

    @property
    def host(self) -> str:
        return self.listen_address[0]

    @property
    def port(self) -> int:
        return self.listen_address[1]


def _version(address: str) -> int | None:
    try:
        return ipaddress.ip_address(address).version
    except ValueError:
        return None


def _resolve(key: str, host: str, value: str) -> str:
    """``host`` as an IP address (an IPv4 one first, for a name that has both)."""
    if _version(host) is not None:
        return host
    try:
        found = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        reason = exc.strerror if isinstance(exc, socket.gaierror) else str(exc)
        raise bad(key, f"cannot resolve {host!r} in {value!r}: {reason} — give an IP address "
                       "(127.0.0.1: this machine only, 0.0.0.0: every interface)") from None
    addresses = [str(info[4][0]) for info in found]
    return next((a for a in addresses if _version(a) == 4), addresses[0])
