"""Zenoh sessions opened from a ``BusConfig`` (``bus/busconfig.py``, which builds the
``zenoh.Config``): waiting for a router, finding the first links, the ports really bound.

>>> from contextlib import closing
>>> cfg = BusConfig(mode="peer", multicast=False)
>>> with closing(open_session(cfg)) as session:
...     len(str(session.zid())) > 0
True
"""

from __future__ import annotations

import ipaddress
import json
import logging
import os
import queue
import re
import socket
import sys
import threading
import time
from dataclasses import dataclass, replace
from typing import Any

import zenoh

from .busconfig import BusConfig, check_endpoint, zenoh_reason
from .errors import ConfigError

log = logging.getLogger(__name__)

# Zenoh reads its links on a runtime of 2 threads ("rx"). Closing a transport whose peer
# vanished can hold one of them for 10 s (a close after a cut, seen with a control session
# at each end: bus/control.py), and a link whose reading task waits behind it has its lease
# noticed only then: a robot cut off was "lost" after 11.5 s instead of its 1.5 s lease, in
# 5 of 12 tries; with 4 threads, 24 of 24 within the lease. Set before Zenoh starts its
# runtimes (on the first session); a ZENOH_RUNTIME of the user's own wins.
os.environ.setdefault("ZENOH_RUNTIME", "(rx: (worker_threads: 4))")

_FIXES = {  # what Zenoh says when a session does not open → what to do
    "Address already in use": "another process listens there: give this one another listen port",
    "Unable to connect": "no router answers there, or it refuses this machine's login: start `sonibus router` "
                         "on that machine, check connect, and user/password or certificates",
    "Cannot assign requested address": "no interface of this machine has that address: listen on 0.0.0.0",
}
DISCOVERY_S = 2.0  # the longest wait for a first link, when there is someone to find
SETTLE_S = 0.25    # after the first link found by multicast: its declarations, the others found in the same round
LINK_SETTLE_S = 0.1  # after the first link to a configured endpoint: its declarations (20 of 20 races refused)


@dataclass(frozen=True)
class _Joined:
    """What ``discover`` and ``listening`` need to know of an open session."""

    window_s: float
    settle_s: float
    lease_s: float
    bound: tuple[str, ...] = ()


_JOINED: dict[str, _Joined] = {}  # by session id


def discover(session: zenoh.Session, served: str = "") -> list[str]:
    """Wait until ``session`` is really on the bus — its first link up, and a moment more
    for the declarations that follow a new link (with multicast, ``SETTLE_S``: also the
    peers found in the same round) — for at most ``DISCOVERY_S``, and not at all when
    there is nobody to find (no multicast, no connect: whoever comes connects to it).
    With ``served`` (a key a query will go to), that moment ends as soon as a queryable
    of it is known (``sonibus send``'s stop: no 100 ms more). The ids of the peers and
    routers it reached."""
    joined = _JOINED.get(str(session.zid()), _Joined(DISCOVERY_S, SETTLE_S, 10.0))
    deadline = time.monotonic() + joined.window_s
    while not links(session):
        if time.monotonic() >= deadline:
            return []
        time.sleep(0.005 if served else 0.02)
    if served:
        querier = session.declare_querier(served)
        try:
            settled = time.monotonic() + joined.settle_s
            # (``.matching``: the status object itself is always true, and this wait ended at once)
            while not querier.matching_status.matching and time.monotonic() < settled:
                time.sleep(0.002)
        finally:
            querier.undeclare()
    else:
        time.sleep(joined.settle_s)
    return links(session)


def links(session: zenoh.Session) -> list[str]:
    """The ids of the routers and peers ``session`` has a link with now (not this process's
    control sessions, ``bus/control.py``: nobody else)."""
    found = [str(z) for z in (*session.info.routers_zid(), *session.info.peers_zid())]
    return [zid for zid in found if zid not in CONTROLS]


CONTROLS: set[str] = set()  # the ids of this process's control sessions (``bus/control.py``)


def find_router(config: BusConfig, timeout_s: float) -> tuple[str, ...]:
    """The endpoints of the first Zenoh router that answers multicast scouting within
    ``timeout_s`` (``()`` if none did)."""
    found: queue.Queue[Any] = queue.Queue()
    scout = zenoh.scout(found.put, what="router", config=replace(config, mode="peer").to_zenoh())
    try:
        hello = found.get(timeout=timeout_s)
    except queue.Empty:
        return ()
    finally:
        scout.stop()
    endpoints = []
    for locator in hello.locators:
        try:
            endpoint = check_endpoint(str(locator))
        except ValueError:  # an address form our checks do not know: Zenoh has the others
            continue
        if not re.match(r"\w+/\[fe80:", endpoint, re.IGNORECASE):  # link-local, and no interface to dial it on
            endpoints.append(endpoint)
    return tuple(sorted(endpoints, key=lambda e: "[" in e))  # IPv4 first


def listening(session: zenoh.Session) -> tuple[str, ...]:
    """The endpoints ``session`` listens on, each with the port it really bound: a listen
    on port 0 (and a peer's default, ``tcp/[::]:0``) as ``tcp/[::]:41234``."""
    return _JOINED.get(str(session.zid()), _Joined(0, 0, 0)).bound


def lease_s(session: zenoh.Session) -> float:
    """The transport lease of ``session`` (how long a vanished peer's tokens last), in s."""
    return _JOINED.get(str(session.zid()), _Joined(0, 0, 10.0)).lease_s


def open_session(config: BusConfig, wait: bool = False) -> zenoh.Session:
    """Open a Zenoh session; the caller closes it with ``session.close()``, or
    ``with contextlib.closing(open_session(cfg)) as session``. Not with the session's
    own ``with``: its exit fails ("Already borrowed") when a Zenoh callback is using
    the session at that instant (a conflict event put as the node stops), and
    ``close()`` does not.

    A client needs its router (at ``connect``, or found by multicast). With ``wait``
    (nodes that run for days) it waits for one, trying every ``reconnect_ms`` —
    Ctrl-C still ends it between tries; without, no router is an error at once."""
    warned = False
    while True:
        joined = _router_found(config, wait)
        if joined is not None:
            try:
                with _OPENING:  # (the sockets that appear while it opens are its own)
                    before = sockets()
                    session = zenoh.open(joined.to_zenoh())
                    after = sockets()
                break
            except ConfigError:
                raise
            except Exception as exc:
                if not (wait and config.mode == "client" and "Unable to connect" in str(exc)):
                    reason = zenoh_reason(exc)
                    fix = next((f" — {fix}" for known, fix in _FIXES.items() if known in reason), "")
                    raise ConfigError(f"cannot open the bus ({config.mode}, listen={list(config.listen)}, "
                                      f"connect={list(joined.connect)}): {reason}{fix}") from exc
        elif not wait:
            raise ConfigError(f"cannot open the bus (client, multicast, namespace '{config.namespace}'): no router "
                              f"answered multicast scouting within {DISCOVERY_S:g} s — start the installation's "
                              f"router machine first, or give connect")
        if not warned:
            log.warning("waiting for a router at %s", ", ".join(config.connect) or "any address (multicast scouting)")
            warned = True
    bound = _bound(joined, {inode: where for inode, where in after.items() if inode not in before})
    searched = config.mode != "client" and (config.multicast or config.connect)
    _JOINED[str(session.zid())] = _Joined(DISCOVERY_S if searched else 0.0,
                                          (SETTLE_S if config.multicast else LINK_SETTLE_S) if searched else 0.0,
                                          config.options.get("transport/link/tx/lease", config.lease_ms) / 1000,
                                          bound)
    return session


_OPENING = threading.Lock()


def _bound(config: BusConfig, new: dict[str, str]) -> tuple[str, ...]:
    """The endpoints ``config`` listens on, a port 0 replaced by the one bound: found among
    ``new``, the sockets that appeared as the session opened (``sockets``)."""
    listen = config.entries().get("listen/endpoints") or default_listen(config.mode)
    free = dict(new)
    out = []
    for endpoint in listen:
        protocol, _, address = endpoint.partition("/")
        host, _, port = re.split(r"[?#]", address, maxsplit=1)[0].rpartition(":")
        if port == "0" and protocol in ("tcp", "udp"):
            wanted = _addresses(host.strip("[]"))
            found = next((inode for inode, bound in free.items() if bound.startswith(protocol + "/")
                          and bound.rpartition(":")[0].partition("/")[2].strip("[]") in wanted), None)
            if found is not None:
                endpoint = free.pop(found)
        out.append(endpoint)
    return tuple(out)


def from_here(endpoint: str) -> str:
    """``endpoint`` as another process of this machine dials it: a listen on every
    interface (``0.0.0.0``, ``[::]``) as loopback.

    >>> from_here("tcp/0.0.0.0:7447"), from_here("tcp/[::]:7447"), from_here("tcp/10.0.0.2:7447")
    ('tcp/127.0.0.1:7447', 'tcp/[::1]:7447', 'tcp/10.0.0.2:7447')
    """
    protocol, _, address = endpoint.partition("/")
    host, colon, port = address.rpartition(":")
    return f"{protocol}/{_WILDCARDS.get(host, host)}{colon}{port}"


_WILDCARDS = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]"}


def default_listen(mode: str) -> list[str]:
    """Where Zenoh listens in ``mode`` when the config says nothing (a peer: ``tcp/[::]:0``)."""
    default = json.loads(zenoh.Config().get_json("listen/endpoints"))
    return list(default.get(mode, []) if isinstance(default, dict) else default)


def _addresses(host: str) -> set[str]:
    """The IP addresses a listen host stands for (a name: what it resolves to)."""
    try:
        return {str(ipaddress.ip_address(host))}
    except ValueError:
        pass
    try:
        return {str(ipaddress.ip_address(info[4][0])) for info in socket.getaddrinfo(host, None)}
    except (OSError, ValueError):
        return set()


def sockets(pid: int | str = "self") -> dict[str, str]:
    """The TCP listeners and unconnected UDP sockets of process ``pid`` (default: this one),
    by inode: ``{"20634": "tcp/[::]:34865"}``, what others can reach it at (Linux's ``/proc``;
    empty elsewhere, where a port 0 stays 0 in ``listening``)."""
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return {}
    inodes = {link[8:-1] for fd in fds if (link := _readlink(f"/proc/{pid}/fd/{fd}")).startswith("socket:[")}
    found = {}
    for table, protocol, state in (("tcp", "tcp", "0A"), ("tcp6", "tcp", "0A"), ("udp", "udp", "07"),
                                   ("udp6", "udp", "07")):
        try:
            with open(f"/proc/{pid}/net/{table}", encoding="ascii") as rows:
                lines = rows.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields_ = line.split()
            if len(fields_) > 9 and fields_[3] == state and fields_[9] in inodes:
                found[fields_[9]] = f"{protocol}/{_address_of(fields_[1])}"
    return found


def _readlink(path: str) -> str:
    try:
        return os.readlink(path)
    except OSError:  # (an fd closed while listed)
        return ""


def _address_of(local: str) -> str:
    """``0100007F:1D27`` → ``127.0.0.1:7463``; an IPv6 one in brackets (``/proc/net/tcp6``)."""
    address, port = local.split(":")
    raw = bytes.fromhex(address)
    if sys.byteorder == "little":  # each 32-bit word is in the host's order
        raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
    ip = ipaddress.ip_address(raw)
    return f"[{ip}]:{int(port, 16)}" if ip.version == 6 else f"{ip}:{int(port, 16)}"


def _router_found(config: BusConfig, wait: bool) -> BusConfig | None:
    """``config`` as Zenoh should open it; None while a client finds no router by multicast.

    Zenoh retries a lost router only at configured endpoints (not at one it scouted),
    so a client that looks for its router by multicast finds it first and then
    connects there: when the router restarts, Zenoh reconnects by itself."""
    if config.mode != "client":
        return config
    if config.multicast and not config.connect:
        found = find_router(config, config.reconnect_ms / 1000 if wait else DISCOVERY_S)
        if not found:
            return None
        config = replace(config, connect=found)
    return replace(config, options={"connect/timeout_ms": config.reconnect_ms, **config.options})
