"""DNS-SD over mDNS (the zeroconf package): ``_oscjson._tcp`` for the OSCQuery server and
``_osc._udp`` for the gateway's port, on the configured interfaces only.

Registering probes the network for about a second and a half, so it runs on a worker;
``close`` sends the goodbyes and closes the sockets (well within a node's 3 s stop).
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import socket
import threading

import ifaddr
from zeroconf import IPVersion, ServiceInfo, Zeroconf

log = logging.getLogger(__name__)

OSCJSON = "_oscjson._tcp.local."
OSC = "_osc._udp.local."


def addresses(host: str, interfaces: tuple[str, ...]) -> list[str]:
    """The IPv4 addresses to bind to and advertise: ``interfaces``, else ``host``, else (a
    wildcard ``host``) every IPv4 address of this machine but loopback's.

    >>> addresses("0.0.0.0", ("10.0.0.2",)), addresses("127.0.0.1", ())
    (['10.0.0.2'], ['127.0.0.1'])
    """
    if interfaces:
        return [a for a in interfaces if ipaddress.ip_address(a).version == 4]
    if not ipaddress.ip_address(host).is_unspecified:
        return [host]
    found = [ip.ip for adapter in ifaddr.get_adapters() for ip in adapter.ips if isinstance(ip.ip, str)]
    return [a for a in found if not ipaddress.ip_address(a).is_loopback]


class Advertiser:
    """Advertises ``name`` as ``_oscjson._tcp`` on ``port`` and ``_osc._udp`` on ``osc_port``
    (at ``osc_host``, or at ``bind`` for a wildcard gateway address), on ``bind`` addresses."""

    def __init__(self, name: str, bind: list[str], port: int, osc_host: str, osc_port: int) -> None:
        self.name, self.bind, self.port, self.osc_port = name, bind, port, osc_port
        self.osc_addresses = bind if ipaddress.ip_address(osc_host).is_unspecified else [osc_host]
        self.registered: list[ServiceInfo] = []
        self._zeroconf: Zeroconf | None = None
        self._lock = threading.Lock()
        self._closed = False

    def _info(self, kind: str, port: int, where: list[str]) -> ServiceInfo:
        host = socket.gethostname().split(".")[0] or "sonibus"
        return ServiceInfo(kind, f"{self.name}.{kind}", port=port, server=f"{host}.local.",
                           addresses=[socket.inet_aton(a) for a in where], properties={"txtvers": "1"})

    def run(self, stopping: threading.Event) -> None:
        """Open zeroconf on the bound addresses and register both services at once (probing
        takes about 1.7 s); returns early, registering no more, once ``stopping`` is set."""
        zc = Zeroconf(interfaces=list(self.bind), ip_version=IPVersion.V4Only)
        with self._lock:
            if self._closed:
                zc.close()
                return
            self._zeroconf = zc
        infos = [self._info(OSCJSON, self.port, self.bind), self._info(OSC, self.osc_port, self.osc_addresses)]
        assert zc.loop is not None
        pending = [asyncio.run_coroutine_threadsafe(_register(zc, info), zc.loop) for info in infos]
        for info, future in zip(infos, pending, strict=True):
            while not future.done():
                if stopping.wait(0.05):
                    for other in pending:
                        other.cancel()
                    return
            future.result()
            self.registered.append(info)
            log.info("mdns: %s advertised on %s", info.name, ", ".join(self.bind))

    def close(self) -> None:
        """Unregister what was registered (the goodbyes) and close zeroconf."""
        with self._lock:
            self._closed = True
            zc, self._zeroconf = self._zeroconf, None
        if zc is None:
            return
        try:
            zc.unregister_all_services()
        finally:
            zc.close()


async def _register(zc: Zeroconf, info: ServiceInfo) -> None:
    announced = await zc.async_register_service(info, allow_name_change=True)
    await announced
