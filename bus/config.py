"""Installation files (TOML): the bus settings and the nodes, in one file.

>>> installation = load("examples/demo.toml")   # doctest: +SKIP
>>> list(installation.nodes)                    # doctest: +SKIP
['pepper', 'sound', 'console']
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .adapter import Adapter
from .busconfig import BusConfig
from .errors import ConfigError, controls, visible
from .keys import check_name
from .logfile import LogConfig
from .options import from_mapping, located

TOP_LEVEL = ("bus", "nodes", "log", "demo")  # [demo]: what the flags of `sonibus demo` set (bus/cli/demo.py)


@dataclass(frozen=True)
class NodeSpec:
    """One ``[nodes.NAME]`` table: the adapter's name and its raw options."""

    name: str
    adapter: str
    options: dict[str, Any] = field(default_factory=dict)
    where: str = ""
    lines: dict[str, int] = field(default_factory=dict)
    host: str = ""   # the machine that runs it; "" for any machine that runs the file
    line: int = 0    # where its table starts

    def config(self, cls: type[Adapter]) -> Any:
        """Its options checked against ``cls.Config``."""
        return from_mapping(cls.Config, self.options, self.where, self.lines)

    def build(self, cls: type[Adapter]) -> Adapter:
        """The adapter, with its options checked against ``cls.Config``."""
        adapter = cls(self.config(cls), name=self.name)
        adapter.kind = self.adapter
        adapter.where = self.at
        return adapter

    def at(self, key: str) -> str:
        """Where ``key`` of this node is set, for messages."""
        return located(self.where, self.lines, key)


@dataclass(frozen=True)
class Installation:
    """A whole installation: how to join the bus, and every node by name."""

    bus: BusConfig
    nodes: dict[str, NodeSpec]
    path: str = ""
    log: LogConfig = field(default_factory=LogConfig)  # [log]: a rotating log file (bus/logfile.py)

    def select(self, only: list[str] | None = None, host: str | None = None) -> list[NodeSpec]:
        """The nodes named in ``only``; else those for ``host`` (nodes pinned to it
        and nodes without a ``host``); else all."""
        if only:
            for name in only:
                if name not in self.nodes:
                    raise ConfigError(f"{self.path}: no node '{name}' — nodes: {', '.join(self.nodes)}")
            return [self.nodes[n] for n in only]
        if host is None:
            return list(self.nodes.values())
        chosen = [spec for spec in self.nodes.values() if spec.host in ("", host)]
        if not chosen:
            hosts = sorted({spec.host for spec in self.nodes.values()})
            raise ConfigError(f"{self.path}: no node for host '{host}' — hosts: {', '.join(hosts)}; "
                              f"use --host NAME or --only NODE")
        return chosen

    def check_owners(self, owned: dict[str, tuple[str, ...]]) -> None:
        """``ConfigError`` if two nodes would own one robot on the same bus (``owned``:
        node → robots). Nodes pinned to other machines count too: they would collide there."""
        owners: dict[tuple[str, str], NodeSpec] = {}
        for name, robots in owned.items():
            spec = self.nodes[name]
            namespace = self.bus.for_host(spec.host).namespace if spec.host else self.bus.namespace
            for robot in robots:
                first = owners.setdefault((namespace, robot), spec)
                if first is not spec:
                    raise ConfigError(
                        f"{self.path}: robot '{robot}' has two owners, {_naming(first, robot)} and "
                        f"{_naming(spec, robot)} — a robot has one owner on the bus: remove one node "
                        f"or give it another robot name")


def _naming(spec: NodeSpec, robot: str) -> str:
    """A node's table and the line of the option that names ``robot`` (else of the table)."""
    names = (key for key, value in spec.options.items()
             if robot == value or (isinstance(value, dict) and robot in value.values()))
    key = next(names, "")
    line = spec.lines.get(key) or spec.line
    return f"[nodes.{spec.name}]" + (f" line {line}" if line else "") + (f" (key '{key}')" if key else "")


def load(path: str | Path) -> Installation:
    """Read and check an installation file; ``ConfigError`` names file, node and key."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    return parse(text, str(path))


def parse(text: str, path: str = "<string>") -> Installation:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    for key in data:
        if key not in TOP_LEVEL:
            line = _line(text, None, key)
            raise ConfigError(f"{path}{f' line {line}' if line else ''}: unknown table '{key}' — "
                              f"known: {', '.join(TOP_LEVEL)}")
    bus_table = data.get("bus", {})
    if not isinstance(bus_table, dict):
        raise ConfigError(f"{path}: 'bus' must be a table")
    bus = from_mapping(BusConfig, bus_table, f"{path} [bus]", _lines(text, "bus", bus_table))
    bus = bus.relative_to(Path(path).resolve().parent)
    for host, override in bus.hosts.items():
        bus.for_host(host, path, _lines(text, f"bus.hosts.{host}", override))
    nodes_table = data.get("nodes", {})
    if not isinstance(nodes_table, dict) or not nodes_table:
        raise ConfigError(f"{path}: no [nodes.NAME] table — an installation needs at least one node")
    nodes = {}
    for name, table in nodes_table.items():
        where = f"{path} [nodes.{visible(name)}]"
        line = _line(text, "nodes", name)
        at_table = f"{where} line {line}" if line else where
        try:
            check_name("node", name)
        except ValueError as exc:
            raise ConfigError(f"{at_table}: {exc}") from None
        if not isinstance(table, dict):
            raise ConfigError(f"{at_table}: must be a table")
        options = dict(table)
        adapter = options.pop("adapter", None)
        host = options.pop("host", "")
        lines = _lines(text, f"nodes.{name}", table)
        if line and not lines:  # an inline table (robot = { adapter = "sim", ... }): every key is on its line
            lines = {key: line for key in table}
        if not isinstance(adapter, str):
            raise ConfigError(f"{at_table}: missing key 'adapter' (a string: see `sonibus adapters`)")
        if not isinstance(host, str):
            raise ConfigError(f"{located(where, lines, 'host')}: key 'host': {host!r} is not a string")
        if controls(host):
            raise ConfigError(f"{located(where, lines, 'host')}: key 'host': '{visible(host)}' holds control "
                              f"characters ({', '.join(controls(host))}) — give the machine's name, as "
                              f"`hostname` prints it")
        nodes[name] = NodeSpec(name, adapter, options, where, lines, host, line)
    log_table = data.get("log", {})
    if not isinstance(log_table, dict):
        raise ConfigError(f"{path}: 'log' must be a table")
    log = from_mapping(LogConfig, log_table, f"{path} [log]", _lines(text, "log", log_table))
    return Installation(bus, nodes, path, log.relative_to(Path(path).resolve().parent))


def _lines(text: str, table: str, keys: Any, depth: int = 3) -> dict[str, int]:
    """The line of each key of ``[table]``, and of the keys of its sub-tables as dotted
    keys (``maps.cutoff.curve``, from ``[nodes.sound.maps.cutoff]``), ``depth`` deep."""
    found = {key: _line(text, table, key) for key in keys}
    out = {key: line for key, line in found.items() if line}
    if depth > 1 and isinstance(keys, dict):
        for key, value in keys.items():
            if isinstance(value, dict):
                nested = _lines(text, f"{table}.{key}", value, depth - 1)
                out.update({f"{key}.{sub}": line for sub, line in nested.items()})
    return out


def _line(text: str, table: str | None, key: str) -> int:
    """The line where ``key`` is set in ``[table]`` (or its own ``[table.key]`` starts),
    0 if not found (for messages)."""
    in_table = table is None
    full = key if table is None else f"{table}.{key}"
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("["):
            if re.match(rf"\[\[?\s*{re.escape(full)}\s*[.\]]", stripped):
                return number
            in_table = stripped.split("#", 1)[0].strip().strip("[]").strip() == table
        elif in_table and re.match(rf"{re.escape(key)}\s*=", stripped):
            return number
    return 0
