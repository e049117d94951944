"""Options of the ``oscquery`` adapter.

    [nodes.oscquery]
    adapter = "oscquery"
    listen = "127.0.0.1:5678"      # HTTP and WebSocket (port 0: any free port)
    gateway = "127.0.0.1:9001"     # the osc-gateway's UDP port, told to clients in HOST_INFO
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from typing import Literal

from sonibus.adapters.osc.config import parse_target
from sonibus.adapters.osc.gateway import parse_endpoint
from sonibus.bus.errors import ConfigError
from sonibus.bus.options import bad


@dataclass(frozen=True)
class OscQueryConfig:
    """Options of the ``oscquery`` adapter."""

    listen: str = "127.0.0.1:5678"             # host:port of HTTP and WebSocket ("0.0.0.0:5678": every interface)
    gateway: str = "127.0.0.1:9001"            # host:port of the osc-gateway that takes the commands
    name: str = "sonibus"                      # HOST_INFO NAME and the mDNS instance name
    values: Literal["raw", "normalized"] = "raw"  # normalized: joints and derived values 0..1, as the OSC sink's
    mdns: bool = True                          # advertise _oscjson._tcp and the gateway's _osc._udp
    interfaces: tuple[str, ...] = ()           # addresses mDNS binds to and advertises (default: the listen host)
    queue: int = 4096                          # samples waiting to be taken; past this the oldest are dropped

    def __post_init__(self) -> None:
        parse_endpoint("listen", self.listen)
        try:
            parse_target(self.gateway)  # (a port clients can send to: not 0)
        except ConfigError as exc:
            raise bad("gateway", f"{exc} — the osc-gateway's listen address") from None
        if not self.name.strip() or "." in self.name:
            raise bad("name", f"{self.name!r} must be a non-empty name without '.' (an mDNS instance name)")
        for address in self.interfaces:
            try:
                ipaddress.ip_address(address)
            except ValueError:
                raise bad("interfaces", f"{address!r} is not an IP address of this machine — "
                                        "give addresses such as \"192.168.1.20\"") from None
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")

    @property
    def host(self) -> str:
        return parse_endpoint("listen", self.listen)[0]

    @property
    def port(self) -> int:
        return parse_endpoint("listen", self.listen)[1]
