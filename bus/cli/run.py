"""Running nodes: ``sonibus run`` (the nodes of an installation file) and ``router``."""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import socket
import sys
from collections.abc import Callable
from dataclasses import replace

from .. import config, runner
from ..adapter import Adapter
from ..busconfig import BusConfig
from ..logfile import LogFile
from ..node import Bus
from ..notify import Notifier
from ..restarts import STOPPED, RunState
from ..session import from_here, listening, open_session
from ..stats import BASE
from ..watchdog import Watchdog
from .api import Command, Environment, Exit, add_bus_arguments, bus_config


def run_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", metavar="CONFIG.toml")
    p.add_argument("--only", nargs="+", metavar="NODE", help="run only these nodes")
    p.add_argument("--host", help="run the nodes of this host (default: this machine's name)")
    p.add_argument("--log-file", metavar="PATH",
                   help="also log to this file, rotated (default: [log] file; [log] max_mb and keep size it)")
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
    cfg = bus_config(args, installation.bus.for_host(host))
    logging_to = replace(installation.log, file=args.log_file) if args.log_file else installation.log
    log_file = LogFile(logging_to) if logging_to.file else None
    state = RunState.for_run(args.config, host, args.only)
    notifier = Notifier()
    names = ", ".join(f"{a.name} ({a.kind})" for a in adapters)

    def say(text: str) -> None:
        if log_file is not None:  # (first: a Ctrl-C just after the line on stdout must not leave it out of the file)
            log_file.note(text)
        env.say(text)

    try:
        restart = state.begin(by_hand=_from_terminal())
        if log_file is not None:
            say(f"sonibus: logging to {log_file.path} (rotated at {logging_to.max_mb:g} MB, {logging_to.keep} kept)")
        if restart.previous and not restart.count:  # (a start by hand after a crash, a power cut...)
            logging.getLogger(__name__).warning("the previous run %s", restart.previous)

        def started(bus: Bus) -> None:
            say(f"sonibus: running {names} on {bus.host}" + (f" — {restart}" if restart.count else ""))
            for line in reached(bus, adapters, cfg, _config_flags(args, installation.bus.for_host(host), cfg, host)):
                say(f"sonibus: {line}")

        runner.run(adapters, cfg, env.stop, on_started=started, host=host, watchdog=Watchdog(notifier, adapters),
                   restart=restart)
    except BaseException as exc:
        how = STOPPED if isinstance(exc, KeyboardInterrupt) else f"failed: {' '.join(str(exc).split())}"
        state.end(how)
        if log_file is not None and how != STOPPED:
            log_file.note(f"sonibus: error: {how.removeprefix('failed: ')}", level=logging.ERROR)
        raise
    else:
        state.end(STOPPED)
    finally:
        with contextlib.suppress(OSError):  # (its output gone: nobody to tell)
            for line in stop_lines(adapters):
                say(line)
        notifier.close()
        if log_file is not None:
            log_file.close()
    # it returns only once a signal set env.stop (its KeyboardInterrupt, which says 130, may be lost on the way:
    # twice in CI it exited 0 on a SIGINT sent while the nodes were starting)
    return Exit.INTERRUPTED


def stop_lines(adapters: list[Adapter]) -> list[str]:
    """A line per node that started: what it counted, the losses too when nothing was lost.

    >>> from sonibus.adapters.sim import SimRobot
    >>> node = SimRobot(name="pepper")
    >>> node.since = 1.0; node.stats.add("sent", 12345); node.stats.add("commands", 2)
    >>> stop_lines([node])
    ['sonibus: stopped pepper (sim): received 0, sent 12,345, dropped 0, stale 0, bad 0, errors 0, commands 2']
    """
    lines = []
    for adapter in adapters:
        if adapter.since:  # (one that never started counted nothing)
            counted = [f"{name} {count:,}" for name, count in adapter.stats.items() if count or name in BASE]
            lines.append(f"sonibus: stopped {adapter.name} ({adapter.kind}): {', '.join(counted)}")
    return lines


def reached(bus: Bus, adapters: list[Adapter], cfg: BusConfig, config_flags: str = "") -> list[str]:
    """Where this process and each of its nodes are reached: the bus (its endpoints with
    the ports really bound, and how another command joins it from this machine), then
    every node's ``address`` (pages, OSC targets, ports, files)."""
    how = f"{cfg.mode}, multicast {'on' if cfg.multicast else 'off'}"
    if cfg.namespace:
        how += f", namespace '{cfg.namespace}'"
    if cfg.connect:
        how += f", connecting to {', '.join(cfg.connect)}"
    listening = bus.listening
    line = f"bus: {how}" + (f", listening on {', '.join(listening)}" if listening else "")
    joins = [flags for flags in (config_flags, _connect_flags(listening, cfg)) if flags]
    if joins:
        line += " — join from this machine with " + ", or ".join(joins)
    return [line] + [f"{a.name}: {a.address}" for a in adapters if a.address]


def _connect_flags(listening: tuple[str, ...], cfg: BusConfig) -> str:
    """``--connect ENDPOINT`` to this process from this machine (a wildcard as loopback)."""
    for endpoint in listening:
        if re.fullmatch(r"(tcp|udp|tls|quic)/.+:\d+", endpoint) and not endpoint.endswith(":0"):
            return f"--connect {from_here(endpoint)}" + ("" if cfg.multicast else " --no-multicast")
    return ""


def _config_flags(args: argparse.Namespace, file: BusConfig, cfg: BusConfig, host: str) -> str:
    """``--config FILE [--host NAME]``, when a one-shot command with them reaches this
    process: the command line changed nothing of the file's bus, and every endpoint it
    listens on has a fixed port (or multicast finds it)."""
    if cfg != file or not (cfg.multicast or (cfg.listen and all(not e.endswith(":0") for e in cfg.listen))):
        return ""
    named = "" if host == socket.gethostname() else f" --host {host}"
    return f"--config {args.config}{named}"


RUN = Command("run", "run the nodes of an installation file", run_arguments, run_installation)


def _router(args: argparse.Namespace, env: Environment) -> Exit:
    cfg = replace(bus_config(args), mode="router")
    if not cfg.listen:
        cfg = replace(cfg, listen=("tcp/0.0.0.0:7447",))
    with contextlib.closing(open_session(cfg)) as session:
        env.say(f"sonibus router {session.zid()} listening on {', '.join(listening(session))}")
        while not env.stop.wait(0.25):
            pass
    return Exit.OK


ROUTER = Command("router", "run a Zenoh router (joins subnets)", lambda p: None, _router, bus=True)


def _from_terminal() -> bool:
    """Whether this run was started by hand, from a terminal (its stdin one): no supervisor's restart."""
    try:
        return os.isatty(sys.stdin.fileno())
    except (AttributeError, ValueError, OSError):  # (no stdin, or one that is not a file)
        return False
