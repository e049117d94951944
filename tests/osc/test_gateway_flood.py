"""Issue 33, item 9: a flood of datagrams faster than the gateway reads them. What the
kernel drops in the socket's full receive buffer is counted in the gateway's stats (as
published on the bus) and said on the log, like the other losses."""

from __future__ import annotations

import logging
import socket

from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.bus import health
from sonibus.bus.udpdrops import KernelDrops

from ..conftest import wait_for
from .test_gateway import build

FLOOD = 20_000  # datagrams, sent as fast as one socket can: many times what the gateway reads meanwhile


def test_what_the_kernel_drops_under_a_flood_is_in_the_stats_and_the_log(net, caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")
    gate = net.start(OscGateway(OscGatewayConfig(listen="127.0.0.1:0"), name="gate"))
    # (a small receive buffer, so the kernel drops some whatever the machine's speed: with the
    # gateway's own 4 MiB, an idle machine's gateway read all 20,000 and one fresh-clone run failed)
    gate._udp.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    packet = build("/flood/trigger", 1)  # an address the gateway ignores, counted: the cheapest to read
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
        for _ in range(FLOOD):
            sender.sendto(packet, gate.udp_address)
    asker = net.bus("asker")

    def settled() -> dict | None:
        """The gateway's stats once every datagram is either read or counted as dropped by the kernel."""
        stats = health.latest(asker, timeout=2.0).get((asker.host, "gate"))
        counters = stats["counters"] if stats else {}
        return stats if counters.get("received", 0) + counters.get("kernel_dropped", 0) == FLOOD else None

    stats = wait_for(settled, 15, "every datagram read or counted as the kernel's drop",
                     lambda: str(health.latest(asker, timeout=2.0).get((asker.host, "gate"), {}).get("counters")))
    dropped = stats["counters"]["kernel_dropped"]
    assert 0 < dropped < FLOOD and stats["counters"]["dropped"] == dropped
    assert "metrics" not in stats  # (the counter is available here: no "unavailable" said)
    said = [r.getMessage() for r in caplog.records if "lost in the kernel's receive buffer" in r.getMessage()]
    assert said and said[0].startswith("gate: ") and "datagrams lost in the kernel's receive buffer" in said[0]


def test_where_the_drop_counter_cannot_be_read_it_says_unavailable_and_counts_nothing():
    """A socket whose counter the kernel will not give (here: one already closed, as on a system
    without SO_MEMINFO, getsockopt fails): no drops made up, no exception on the receive path."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.close()
    drops = KernelDrops(sock)
    assert (drops.available, drops.new(), drops.total, repr(drops)) == (False, 0, 0, "<KernelDrops unavailable>")
