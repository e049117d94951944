"""Zenoh sessions from a typed config: the one place that builds ``zenoh.Config``.

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
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import zenoh

from .errors import ConfigError
from .keys import NOT_IN_NAMES
from .options import bad, from_mapping

log = logging.getLogger(__name__)

# Zenoh reads its links on a runtime of 2 threads ("rx"). Closing a transport whose peer
# vanished can hold one of them for 10 s (a close after a cut, seen with a control session
# at each end: bus/control.py), and a link whose reading task waits behind it has its lease
# noticed only then: a robot cut off was "lost" after 11.5 s instead of its 1.5 s lease, in
# 5 of 12 tries; with 4 threads, 24 of 24 within the lease. Set before Zenoh starts its
# runtimes (on the first session); a ZENOH_RUNTIME of the user's own wins.
os.environ.setdefault("ZENOH_RUNTIME", "(rx: (worker_threads: 4))")

MODES = ("peer", "client", "router")
TLS_KEYS = ("root_ca", "cert", "key", "mutual")
ADDRESSED = ("tcp", "udp", "tls", "quic", "ws")  # <protocol>/<host>:<port>
PROTOCOLS = (*ADDRESSED, "unixsock-stream", "unixpipe", "serial", "vsock")
ZENOH_OPTIONS = "Zenoh's DEFAULT_CONFIG.json5 (github.com/eclipse-zenoh/zenoh)"
_FIELDS = {"namespace": "namespace", "access_control": "access_control",
           "connect/endpoints": "connect", "listen/endpoints": "listen"}  # Zenoh key → ours, for errors
_FIXES = {  # what Zenoh says when a session does not open → what to do
    "Address already in use": "another process listens there: give this one another listen port",
    "Unable to connect": "no router answers there, or it refuses this machine's login: start `sonibus router` "
                         "on that machine, check connect, and user/password or certificates",
    "Cannot assign requested address": "no interface of this machine has that address: listen on 0.0.0.0",
}
DISCOVERY_S = 2.0  # the longest wait for a first link, when there is someone to find
SETTLE_S = 0.25    # after the first link found by multicast: its declarations, the others found in the same round
LINK_SETTLE_S = 0.1  # after the first link to a configured endpoint: its declarations (20 of 20 races refused)
_HOST_NAME = re.compile(r"[A-Za-z0-9]([A-Za-z0-9_.-]*[A-Za-z0-9])?\Z")
_LIBRARY_SOURCE = re.compile(r"\s+at /\S+\.rs:\d+\.?")


@dataclass(frozen=True)
class BusConfig:
    """How a process joins the bus (the ``[bus]`` table of a configuration).

    The defaults suit installations: a lost link or robot is noticed within
    ``lease_ms`` (Zenoh's transport lease) and a link that comes back is retried
    at least every ``reconnect_ms``. ``user``/``password``/``users_file``, ``tls``
    and ``access_control`` are Zenoh's own authentication, TLS and ACL settings;
    ``options`` are raw Zenoh entries (``{"transport/link/tx/lease": 2000}``)
    applied last. ``hosts`` holds per-machine overrides (``[bus.hosts.NAME]``).
    """

    mode: str = "peer"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast: bool = True
    namespace: str = ""
    lease_ms: int = 1500
    reconnect_ms: int = 1000
    max_future_s: float = 5.0          # clock-skew tolerance: data stamped further ahead of this machine is refused
    user: str = ""
    password: str = ""
    users_file: str = ""
    tls: dict[str, Any] = field(default_factory=dict)
    access_control: dict[str, Any] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)
    hosts: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise bad("mode", f"'{self.mode}' is not one of {', '.join(MODES)}")
        if self.lease_ms < 500:
            raise bad("lease_ms", f"{self.lease_ms} is too short: Zenoh keeps a link alive with "
                      "4 messages per lease, so under 500 ms a busy machine loses links")
        if self.reconnect_ms < 100:
            raise bad("reconnect_ms", f"{self.reconnect_ms} must be at least 100")
        if not 0 < self.max_future_s <= 86400:
            raise bad("max_future_s", f"{self.max_future_s:g} must be more than 0 s and at most a day "
                      "(put the machines' clocks in step: NTP)")
        if bool(self.user) != bool(self.password):
            raise bad("password" if self.user else "user", "user and password go together")
        unknown = sorted(set(self.tls) - set(TLS_KEYS))
        if unknown:
            raise bad("tls", f"unknown key '{unknown[0]}' — known keys: {', '.join(TLS_KEYS)}")
        if self.tls and not self.tls.get("root_ca"):
            raise bad("tls", "needs root_ca, the certificate of the authority that signed every node's cert")
        if bool(self.tls.get("cert")) != bool(self.tls.get("key")):
            raise bad("tls", "cert and key go together")
        for name, override in self.hosts.items():
            if not isinstance(override, dict):
                raise bad("hosts", f"[bus.hosts.{name}] must be a table")
            if "hosts" in override:
                raise bad("hosts", f"[bus.hosts.{name}] cannot have hosts of its own")
        if self.namespace and not all(c and not set(c) & set(NOT_IN_NAMES) for c in self.namespace.split("/")):
            raise bad("namespace", f"'{self.namespace}' must be plain key chunks joined by '/' (no '*', '$', "
                      "'?', '#', '@', spaces or empty chunks), e.g. \"museum\" or \"museum/hall1\"")
        for key, endpoints in (("connect", self.connect), ("listen", self.listen)):
            for endpoint in endpoints:
                try:
                    check_endpoint(endpoint, listen=key == "listen")
                except ValueError as exc:
                    raise bad(key, str(exc)) from None
        self.to_zenoh()  # what only Zenoh knows (its option names and types), found now, not at open

    def for_host(self, host: str, where: str = "", lines: dict[str, int] | None = None) -> BusConfig:
        """This config with the ``[bus.hosts.HOST]`` overrides applied (if any);
        ``where`` (the file) and ``lines`` (of the override's keys) go into errors."""
        override = self.hosts.get(host)
        if not override:
            return self
        base = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "hosts"}
        return from_mapping(BusConfig, {**base, **override}, f"{where} [bus.hosts.{host}]".lstrip(), lines)

    def relative_to(self, folder: Path) -> BusConfig:
        """File names (TLS files, users file) taken relative to ``folder``, the configuration's."""
        def paths(table: dict[str, Any]) -> dict[str, Any]:
            out = dict(table)
            if isinstance(out.get("tls"), dict):
                out["tls"] = {k: v if k == "mutual" else _under(folder, v) for k, v in out["tls"].items()}
            if out.get("users_file"):
                out["users_file"] = _under(folder, out["users_file"])
            return out

        top = paths({"tls": self.tls, "users_file": self.users_file})
        return replace(self, **top, hosts={name: paths(o) for name, o in self.hosts.items()})

    def entries(self) -> dict[str, Any]:
        """The Zenoh configuration entries this config stands for."""
        entries: dict[str, Any] = {
            "mode": self.mode, "scouting/multicast/enabled": self.multicast,
            "transport/link/tx/lease": self.lease_ms,
            "connect/retry": {"period_init_ms": min(250, self.reconnect_ms), "period_max_ms": self.reconnect_ms,
                              "period_increase_factor": 2},
        }
        if self.connect:
            entries["connect/endpoints"] = list(self.connect)
        if self.listen:
            entries["listen/endpoints"] = list(self.listen)
        if self.namespace:
            entries["namespace"] = self.namespace
        if self.user:
            entries["transport/auth/usrpwd/user"] = self.user
            entries["transport/auth/usrpwd/password"] = self.password
        if self.users_file:
            entries["transport/auth/usrpwd/dictionary_file"] = self.users_file
        if self.tls:
            tls = "transport/link/tls/"
            entries[tls + "root_ca_certificate"] = self.tls["root_ca"]
            if self.tls.get("cert"):
                for side in ("listen", "connect"):
                    entries[f"{tls}{side}_certificate"] = self.tls["cert"]
                    entries[f"{tls}{side}_private_key"] = self.tls["key"]
            entries[tls + "enable_mtls"] = bool(self.tls.get("mutual", False))
        if self.access_control:
            entries["access_control"] = {"enabled": True, **self._namespaced(self.access_control)}
        entries.update(self.options)
        return entries

    def _namespaced(self, acl: dict[str, Any]) -> dict[str, Any]:
        """Zenoh checks ACL rules against keys as they travel, with the namespace in
        front: rules are written without it, like every other key in sonibus."""
        if not self.namespace:
            return acl
        rules = [{**rule, "key_exprs": [f"{self.namespace}/{k}" for k in rule.get("key_exprs", [])]}
                 if isinstance(rule, dict) else rule for rule in acl.get("rules", [])]
        return {**acl, "rules": rules}

    def to_zenoh(self) -> zenoh.Config:
        """The ``zenoh.Config``; ``ConfigError`` names the key of this config Zenoh refused."""
        config = zenoh.Config()
        for key, value in self.entries().items():
            try:
                _insert(config, key, value)
            except ValueError as exc:
                raise bad("options" if key in self.options else _FIELDS.get(key, key), str(exc)) from None
        return config


def check_option(key: str, value: Any) -> None:
    """``ValueError`` if Zenoh has no option ``key`` (``transport/link/tx/lease``) or
    refuses ``value`` for it, saying in one line what and how to find the right one."""
    _insert(zenoh.Config(), key, value)


def _insert(config: zenoh.Config, key: str, value: Any) -> None:
    text = json.dumps(value)
    try:
        config.insert_json5(key, text)
    except Exception as exc:  # zenoh's ZError: a Rust debug string with source paths
        reason = zenoh_reason(exc)
        if reason == "unknown key":
            raise ValueError(f"'{key}' is not a Zenoh option — check its spelling in {ZENOH_OPTIONS}") from None
        shown = text if len(text) <= 60 else text[:57] + "..."
        raise ValueError(f"Zenoh refuses {key} = {shown}: {reason} — see {ZENOH_OPTIONS}") from None


def zenoh_reason(exc: BaseException) -> str:
    """Zenoh's message without the Rust wrapping and source paths, for one line."""
    text = str(exc)
    found = re.search(r'msg: "((?:[^"\\]|\\.)*)"', text) or re.search(r'Str\("((?:[^"\\]|\\.)*)"\)', text)
    if found:
        text = found[1].replace('\\"', '"')
    return " ".join(_LIBRARY_SOURCE.sub("", text).split()).rstrip(".")


def check_endpoint(endpoint: str, listen: bool = False) -> str:
    """``endpoint`` if it is one Zenoh can use (``tcp/192.168.1.10:7447``,
    ``tcp/[::1]:7447``); else ``ValueError`` saying what is wrong and the fix.
    A ``listen`` port may be 0 (any free port), a connect port may not.

    >>> check_endpoint("tcp/[::1]:7447")
    'tcp/[::1]:7447'
    >>> check_endpoint("tcp/127.0.0.1:0")
    Traceback (most recent call last):
    ValueError: 'tcp/127.0.0.1:0': port 0 is out of range — give one from 1 to 65535 (0, any free port, ...)
    """
    protocol, slash, address = endpoint.partition("/")
    example = "e.g. tcp/192.168.1.10:7447"
    if not slash or not protocol or not address:
        raise ValueError(f"'{endpoint}' is not an endpoint — write <protocol>/<host>:<port>, {example}")
    if protocol not in PROTOCOLS:
        raise ValueError(f"'{endpoint}': unknown protocol '{protocol}' — one of {', '.join(PROTOCOLS)}")
    if protocol not in ADDRESSED:
        return endpoint
    address = re.split(r"[?#]", address, maxsplit=1)[0]  # ?metadata and #config are Zenoh's own
    host, colon, port = address.rpartition(":")
    if not colon or not host:
        raise ValueError(f"'{endpoint}': no {'port' if host or not colon else 'host'} — "
                         f"write {protocol}/<host>:<port>, {example}")
    if not port.isdigit():
        raise ValueError(f"'{endpoint}': port '{port}' is not a number — write {protocol}/<host>:<port>, {example}")
    if not (0 if listen else 1) <= int(port) <= 65535:
        ports = "0 (any free port) to 65535" if listen else "1 to 65535 (0, any free port, only suits listen)"
        raise ValueError(f"'{endpoint}': port {int(port)} is out of range — give one from {ports}")
    problem = _host_problem(host)
    if problem:
        raise ValueError(f"'{endpoint}': {problem}")
    return endpoint


def _host_problem(host: str) -> str:
    """What is wrong with the host part of an endpoint ("" if nothing)."""
    if host.startswith("[") or ":" in host:
        if not (host.startswith("[") and host.endswith("]")):
            return f"an IPv6 address goes in brackets, e.g. tcp/[{host.strip('[]')}]:7447"
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            return f"'{host[1:-1]}' is not an IPv6 address"
        return ""
    if re.fullmatch(r"[0-9.]+", host):
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            return f"'{host}' is not an IPv4 address"
        return ""
    return "" if _HOST_NAME.match(host) else f"'{host}' is not a host name or an IP address"


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


def _under(folder: Path, name: Any) -> Any:
    return str(folder / name) if isinstance(name, str) and name and not Path(name).is_absolute() else name
