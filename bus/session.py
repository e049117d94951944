"""Zenoh sessions from a typed config: the one place that builds ``zenoh.Config``.

>>> cfg = BusConfig(mode="peer", multicast=False)
>>> with open_session(cfg) as session:
...     len(str(session.zid())) > 0
True
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import zenoh

from .errors import ConfigError
from .options import bad, from_mapping

log = logging.getLogger(__name__)

MODES = ("peer", "client", "router")
TLS_KEYS = ("root_ca", "cert", "key", "mutual")


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

    def for_host(self, host: str) -> BusConfig:
        """This config with the ``[bus.hosts.HOST]`` overrides applied (if any)."""
        override = self.hosts.get(host)
        if not override:
            return self
        base = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "hosts"}
        return from_mapping(BusConfig, {**base, **override}, f"[bus.hosts.{host}]")

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
        config = zenoh.Config()
        for key, value in self.entries().items():
            try:
                config.insert_json5(key, json.dumps(value))
            except Exception as exc:  # zenoh raises ZError with the parser's text
                raise ConfigError(f"bus option '{key}' = {json.dumps(value)} rejected by Zenoh: {exc}") from exc
        return config


def open_session(config: BusConfig, wait: bool = False) -> zenoh.Session:
    """Open a Zenoh session; the caller closes it (it is a context manager).

    A client needs its router. With ``wait`` (nodes that run for days) it waits
    for one, trying every ``reconnect_ms`` — Ctrl-C still ends it between tries;
    without, no router is an error at once."""
    if config.mode == "client" and config.connect:
        config = replace(config, options={"connect/timeout_ms": config.reconnect_ms, **config.options})
    warned = False
    while True:
        try:
            return zenoh.open(config.to_zenoh())
        except ConfigError:
            raise
        except Exception as exc:
            if not (wait and config.mode == "client" and "Unable to connect" in str(exc)):
                raise ConfigError(f"cannot open the bus ({config.mode}, listen={list(config.listen)}, "
                                  f"connect={list(config.connect)}): {str(exc).split(' at /')[0]}") from exc
            if not warned:
                log.warning("waiting for a router at %s", ", ".join(config.connect))
                warned = True


def _under(folder: Path, name: Any) -> Any:
    return str(folder / name) if isinstance(name, str) and name and not Path(name).is_absolute() else name
