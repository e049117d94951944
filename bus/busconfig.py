"""How a process joins the bus, as a typed config (``BusConfig``, the ``[bus]`` table of a
configuration), and what only Zenoh knows of it checked at once: option names and values,
endpoints. ``bus/session.py`` opens a session from it.

>>> cfg = BusConfig(mode="peer", multicast=False, lease_ms=2000)
>>> cfg.entries()["transport/link/tx/lease"]
2000
>>> check_endpoint("tcp/127.0.0.1")
Traceback (most recent call last):
ValueError: 'tcp/127.0.0.1': no port — write tcp/<host>:<port>, e.g. tcp/192.168.1.10:7447
"""

from __future__ import annotations

import ipaddress
import json
import re
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import zenoh

from .keys import NOT_IN_NAMES
from .options import bad, from_mapping

__all__ = ["ADDRESSED", "MODES", "PROTOCOLS", "BusConfig", "check_endpoint", "check_option", "zenoh_reason"]


MODES = ("peer", "client", "router")
TLS_KEYS = ("root_ca", "cert", "key", "mutual")
ADDRESSED = ("tcp", "udp", "tls", "quic", "ws")  # <protocol>/<host>:<port>
PROTOCOLS = (*ADDRESSED, "unixsock-stream", "unixpipe", "serial", "vsock")
ZENOH_OPTIONS = "Zenoh's DEFAULT_CONFIG.json5 (github.com/eclipse-zenoh/zenoh)"
_FIELDS = {"namespace": "namespace", "access_control": "access_control",
           "connect/endpoints": "connect", "listen/endpoints": "listen"}  # Zenoh key → ours, for errors
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



def _under(folder: Path, name: Any) -> Any:
    return str(folder / name) if isinstance(name, str) and name and not Path(name).is_absolute() else name
