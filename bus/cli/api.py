"""What a subcommand is made of — the one module a plug-in's subcommand imports.

A package adds ``sonibus NAME`` by registering a ``Command`` in the
``sonibus.commands`` entry-point group, as the built-in commands are registered::

    [project.entry-points."sonibus.commands"]
    count = "my_package.cli:COUNT"

    COUNT = Command("count", "count lines", arguments, run)   # run(args, env) -> Exit
"""

from __future__ import annotations

import argparse
import contextlib
import enum
import ipaddress
import json
import re
import socket
import sys
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any, TextIO

from .. import config
from ..busconfig import MODES, BusConfig, check_endpoint, check_option
from ..control import open_control
from ..errors import ConfigError
from ..node import Bus
from ..session import default_listen, from_here, open_session

COMMAND_GROUP = "sonibus.commands"
DEMO_BUS = "tcp/127.0.0.1:7448"  # where `sonibus demo` listens (adapters/demo.toml): this machine only
DEMO_LISTEN = "tcp/127.0.0.1:0"  # where a process that joins the demo listens (for its peers, gossiped): loopback


class Exit(enum.IntEnum):
    """Exit statuses: 1 error, 2 usage or configuration (a bad flag, file, table or
    key), 3 robot not found, 4 command refused, 5 the robot did not answer (a timeout,
    a robot that is not connected or does not answer, a stop that did not reach it),
    130 interrupted (Ctrl-C, SIGTERM), 141 the output was closed (``sonibus info F |
    head -1``: quiet, as a Unix tool killed by SIGPIPE)."""

    OK = 0
    ERROR = 1
    USAGE = 2
    NOT_FOUND = 3
    REFUSED = 4
    TIMEOUT = 5
    INTERRUPTED = 130
    OUTPUT_CLOSED = 141


@dataclass
class Environment:
    """Where the CLI reads and writes; tests pass their own."""

    stdout: TextIO = field(default_factory=lambda: sys.stdout)
    stderr: TextIO = field(default_factory=lambda: sys.stderr)
    stop: threading.Event = field(default_factory=threading.Event)

    def say(self, text: str) -> None:
        """A line on stdout; ``BrokenPipeError`` once its reader went away (the CLI ends quietly)."""
        line(self.stdout, text)

    def hint(self, text: str) -> None:
        """A ``sonibus: hint: ...`` line on stderr."""
        line(self.stderr, f"sonibus: hint: {text}")


def line(stream: TextIO, text: str) -> None:
    """``text`` and its newline in one write: ``print`` writes them apart, and unbuffered (as
    under PYTHONUNBUFFERED) a log line from another thread came between, on the same pipe."""
    stream.write(text + "\n")
    stream.flush()


@dataclass(frozen=True)
class Command:
    """A subcommand, registered in the ``sonibus.commands`` entry-point group under its
    name (``record = "sonibus.adapters.recorder.cli:RECORD"``): the core knows none by name.

    ``arguments`` adds its options to the subparser; ``run`` returns an exit status.
    With ``bus=True`` it also takes the bus options and ``--config``/``--host`` (read
    them with ``bus_config(args)``); a command whose own options clash with those
    adds the bus options itself with ``add_bus_arguments(parser, installation=False)``."""

    name: str
    help: str
    arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace, Environment], int]
    bus: bool = False


def add_bus_arguments(parser: argparse.ArgumentParser, installation: bool = True, demo: bool = True) -> None:
    """The options that say how to join the bus; with ``installation``, also
    ``--config FILE`` and ``--host NAME`` (join as that machine of an installation file);
    with ``demo``, ``--demo`` (join this machine's ``sonibus demo``)."""
    group = parser.add_argument_group("bus")
    group.add_argument("--mode", choices=MODES, help="Zenoh mode (default: peer)")
    group.add_argument("--connect", action="append", metavar="ENDPOINT", help="e.g. tcp/192.168.1.10:7447")
    group.add_argument("--listen", action="append", metavar="ENDPOINT", help="e.g. tcp/0.0.0.0:7447")
    group.add_argument("--no-multicast", action="store_true", help="do not discover peers by multicast")
    group.add_argument("--namespace", help="prefix that keeps this installation apart from others")
    group.add_argument("--zenoh", action="append", metavar="KEY=JSON", default=[],
                       help="raw Zenoh option, e.g. transport/link/tx/lease=2000")
    if demo:
        group.add_argument("--demo", action="store_true",
                           help=f"join this machine's `sonibus demo` (private: no multicast, connect {DEMO_BUS}, "
                                "listen on loopback only)")
    if installation:
        group = parser.add_argument_group("installation")
        group.add_argument("--config", dest="bus_file", metavar="CONFIG.toml",
                           help="join the bus of this installation file, where its `sonibus run` listens")
        group.add_argument("--host", help="with --config: use its [bus.hosts.HOST] settings (default: this machine)")


def bus_config(args: argparse.Namespace, base: BusConfig | None = None) -> BusConfig:
    """``base`` (or the ``--config`` file's, or defaults) with the command-line bus options applied."""
    if base is None and getattr(args, "bus_file", None):
        base = visiting(config.load(args.bus_file).bus.for_host(args.host or socket.gethostname()))
    cfg = base or BusConfig()
    changes: dict[str, Any] = {}
    if args.mode:
        changes["mode"] = args.mode
    for flag in ("connect", "listen"):
        for endpoint in getattr(args, flag) or ():
            try:
                check_endpoint(endpoint, listen=flag == "listen")
            except ValueError as exc:
                raise ConfigError(f"--{flag} {exc}") from None
        if getattr(args, flag):
            changes[flag] = tuple(getattr(args, flag))
    if getattr(args, "demo", False):
        # the demo's bus instead of a file's (a `run` or --config file's connect and listen are for a LAN)
        changes.update(multicast=False, connect=(*changes.get("connect", ()), DEMO_BUS),
                       listen=private(changes.get("listen", ())))
    if args.no_multicast:
        changes["multicast"] = False
    if args.namespace is not None:
        changes["namespace"] = args.namespace
    if args.zenoh:
        changes["options"] = _zenoh_options(args.zenoh, dict(cfg.options))
    try:
        return replace(cfg, **changes) if changes else cfg
    except ConfigError as exc:  # "key 'namespace': ..." from BusConfig: name the flag instead
        flags = {"namespace": "--namespace", "options": "--zenoh", "mode": "--mode"}
        raise ConfigError(re.sub(r"^key '(\w+)'", lambda m: flags.get(m[1], m[0]), str(exc))) from None


def private(listen: tuple[str, ...]) -> tuple[str, ...]:
    """Where a process that joins this machine's demo listens: ``listen`` (given with
    ``--listen``) if every endpoint is on loopback, ``DEMO_LISTEN`` if none is given
    (Zenoh's own default, ``tcp/[::]:0``, is every interface); else ``ConfigError``.

    >>> private(()), private(("tcp/[::1]:7500",))
    (('tcp/127.0.0.1:0',), ('tcp/[::1]:7500',))
    >>> private(("tcp/0.0.0.0:7500",))
    Traceback (most recent call last):
    sonibus.bus.errors.ConfigError: --listen tcp/0.0.0.0:7500: --demo keeps to this machine — listen on loopback ...
    """
    for endpoint in listen:
        if not on_loopback(endpoint):
            raise ConfigError(f"--listen {endpoint}: --demo keeps to this machine — listen on loopback "
                              "(tcp/127.0.0.1:PORT or tcp/[::1]:PORT), or leave --demo out to join a network")
    return listen or (DEMO_LISTEN,)


def on_loopback(endpoint: str) -> bool:
    """Whether ``endpoint`` (``tcp/127.0.0.1:7448``, ``tcp/[::1]:0``) is on this machine's loopback only.

    >>> on_loopback("tcp/127.0.0.1:0"), on_loopback("tcp/[::1]:7448"), on_loopback("tcp/[::]:0")
    (True, True, False)
    """
    address = re.split(r"[?#]", endpoint.partition("/")[2], maxsplit=1)[0]
    host = address.rpartition(":")[0].strip("[]")
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def visiting(cfg: BusConfig) -> BusConfig:
    """How a command joins the machine whose ``sonibus run`` uses ``cfg``: it dials where
    that process listens (from this machine: a wildcard as loopback) instead of listening
    on the same port, and a router's machine is joined as the router's client.

    >>> joined = visiting(BusConfig(multicast=False, listen=("tcp/0.0.0.0:7450",)))
    >>> joined.connect, joined.listen
    (('tcp/127.0.0.1:7450',), ())
    """
    listen = cfg.listen or (tuple(default_listen("router")) if cfg.mode == "router" else ())
    here = tuple(from_here(e) for e in listen if not e.endswith(":0"))  # (a port 0: only `run` knows which)
    return replace(cfg, mode="client" if cfg.mode == "router" else cfg.mode, listen=(),
                   connect=tuple(dict.fromkeys(cfg.connect + here)))


def _zenoh_options(items: list[str], options: dict[str, Any]) -> dict[str, Any]:
    """``options`` with each ``--zenoh KEY=JSON`` set, every one checked."""
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--zenoh '{item}' is not KEY=JSON, e.g. --zenoh transport/link/tx/lease=2000")
        try:
            options[key] = json.loads(value)
        except json.JSONDecodeError:
            options[key] = value  # a bare word: --zenoh mode=client
        try:
            check_option(key, options[key])
        except ValueError as exc:
            raise ConfigError(f"--zenoh '{item}': {exc}") from None
    return options


@contextlib.contextmanager
def joined(cfg: BusConfig, node: str = "", control: bool = False) -> Iterator[Bus]:
    """A ``Bus`` on a session of its own for one command, closed at the end; with
    ``control``, its control session too (``bus/control.py``: a command that stays and stops)."""
    with contextlib.closing(open_session(cfg)) as session:
        if not control:
            yield Bus(session, node=node)
            return
        with contextlib.closing(open_control(cfg, session)) as urgent:
            yield Bus(session, node=node, control=urgent)
