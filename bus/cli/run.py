"""Running nodes: ``sonibus run`` (the nodes of an installation file) and ``router``."""

from __future__ import annotations

import argparse
import contextlib
import socket
from collections.abc import Callable
from dataclasses import replace

from .. import config, runner
from ..adapter import Adapter
from ..node import Bus
from ..session import open_session
from .api import Command, Environment, Exit, add_bus_arguments, bus_config


def run_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", metavar="CONFIG.toml")
    p.add_argument("--only", nargs="+", metavar="NODE", help="run only these nodes")
    p.add_argument("--host", help="run the nodes of this host (default: this machine's name)")
    add_bus_arguments(p, installation=False)


def run_installation(args: argparse.Namespace, env: Environment,
                     prepare: Callable[[list[Adapter]], None] | None = None) -> Exit:
    """``sonibus run``; ``prepare`` sees the adapters built before they start (``sonibus rehearse``
    sets its shows' clocks)."""
    installation = config.load(args.config)
    host = args.host or socket.gethostname()
    adapters = runner.build(installation, args.only, host)
    if prepare is not None:
        prepare(adapters)
    names = ", ".join(f"{a.name} ({a.kind})" for a in adapters)

    def started(bus: Bus) -> None:
        env.say(f"sonibus: running {names} on {bus.host}")
        for adapter in adapters:
            if adapter.address:
                env.say(f"sonibus: {adapter.name}: {adapter.address}")

    runner.run(adapters, bus_config(args, installation.bus.for_host(host)), env.stop, on_started=started, host=host)
    # it returns only once a signal set env.stop (its KeyboardInterrupt, which says 130, may be lost on the way:
    # twice in CI it exited 0 on a SIGINT sent while the nodes were starting)
    return Exit.INTERRUPTED


RUN = Command("run", "run the nodes of an installation file", run_arguments, run_installation)


def _router(args: argparse.Namespace, env: Environment) -> Exit:
    cfg = replace(bus_config(args), mode="router")
    if not cfg.listen:
        cfg = replace(cfg, listen=("tcp/0.0.0.0:7447",))
    with contextlib.closing(open_session(cfg)) as session:
        env.say(f"sonibus router {session.zid()} listening on {', '.join(cfg.listen)}")
        while not env.stop.wait(0.25):
            pass
    return Exit.OK


ROUTER = Command("router", "run a Zenoh router (joins subnets)", lambda p: None, _router, bus=True)
