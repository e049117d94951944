"""Running nodes: build adapters from an installation, start them, stop them all."""

from __future__ import annotations

import contextlib
import logging
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path

from . import keys, registry
from .adapter import Adapter
from .busconfig import BusConfig
from .config import Installation
from .control import open_control
from .errors import AdapterError, ConfigError, NodeFailed
from .memory import Trimmer
from .messages import Limits
from .node import Bus
from .notify import Notifier
from .owner import RobotAdapter
from .plan import planned
from .restarts import Restart
from .session import open_session
from .watchdog import Watchdog

log = logging.getLogger(__name__)


def build(installation: Installation, only: list[str] | None = None, host: str | None = None) -> list[Adapter]:
    """Every selected node's adapter, configured; all errors before anything starts,
    two owners of one robot among all the file's nodes too (not only the selected)."""
    adapters = []
    for spec in installation.select(only, host):
        try:
            cls = registry.load(spec.adapter)
        except AdapterError as exc:
            raise ConfigError(f"{spec.at('adapter')}: key 'adapter': {exc}") from None
        adapter = spec.build(cls)
        adapter.file = Path(installation.path).resolve() if installation.path else None
        adapter.folder = adapter.file.parent if adapter.file else None
        adapters.append(adapter)
    installation.check_owners(_owned_robots(installation))
    return adapters


def _owned_robots(installation: Installation) -> dict[str, tuple[str, ...]]:
    """Node → the robots it will own, for every node whose adapter loads and whose
    options are valid (the others are checked where they run)."""
    owned = {}
    for spec in installation.nodes.values():
        try:
            cls = registry.load(spec.adapter)
            owned[spec.name] = cls.owned_robots(spec.config(cls))
        except (AdapterError, ConfigError):
            continue
    return owned


def run(adapters: list[Adapter], bus_config: BusConfig, stop: threading.Event,
        on_started: Callable[[Bus], None] | None = None, host: str | None = None,
        watchdog: Watchdog | None = None, restart: Restart | None = None) -> None:
    """Open one session, start ``adapters`` in order, wait for ``stop``, stop them in
    reverse order and close the session — also on Ctrl-C or an error. ``host`` names
    this machine on the bus (default: its hostname). A node that fails (a worker
    died) stops them all too, and ``NodeFailed`` says which and why: the process ends
    with an error, and its supervisor restarts it.

    ``watchdog`` tells a supervisor (systemd) how it goes: joining, each node starting,
    ready, healthy or not (``bus/watchdog.py``). ``restart`` (``bus/restarts.py``): when
    this process is a supervisor's restart, every node reports it in its stats and a
    ``node`` event with state ``restarted`` says so, once every node has started.

    While it waits, what glibc's malloc keeps free after a burst goes back to the system
    (``bus/memory.py``): a flood must not leave the process at its high-water mark."""
    watchdog = watchdog or Watchdog(Notifier({}), adapters)
    trimmer = Trimmer()
    restart = restart or Restart()
    with contextlib.ExitStack() as closing:
        with watchdog.joining(f"joining the bus ({_joining(bus_config)})"):
            session = closing.enter_context(contextlib.closing(open_session(bus_config, wait=True)))
        # a control session only where robots are owned: a sink's stop leaves from its data session and
        # reaches the owner's control session over the link that one dialled (docs/design.md)
        owner = any(isinstance(adapter, RobotAdapter) for adapter in adapters)
        control = closing.enter_context(contextlib.closing(open_control(bus_config, session))) if owner else None
        bus = Bus(session, host=host, limits=Limits(max_future_s=bus_config.max_future_s), control=control)
        # what the nodes will subscribe to, before any does: a robot's frames reach one Zenoh subscriber
        # of the process, whichever node of one robot or of every robot starts first (bus/fanout.py)
        bus.plan(k for adapter in adapters for k in planned(adapter.config))
        started: list[Adapter] = []
        why = "stopped"
        try:
            for adapter in adapters:
                watchdog.status(f"starting node '{adapter.name}' ({adapter.kind})")
                adapter.restarts = restart.count
                adapter.when_failed(stop.set)
                try:
                    adapter.start(bus)
                except ConfigError as exc:
                    raise _located(adapter, exc) from None
                started.append(adapter)
                log.info("started %r", adapter)
            if restart.count:
                _announce(bus, started, restart)
            if on_started is not None:
                on_started(bus)
            watchdog.ready(f"running {', '.join(a.name for a in started)} on {bus.host}"
                           + (f" (restart {restart.count})" if restart.count else ""))
            # woken by a stop, by a node that fails (it sets ``stop``: every node stops, NodeFailed says
            # why), or when the watchdog or the trimmer may be due: not ten times a second for nothing
            every_s = min(watchdog.every_s, trimmer.every_s)
            while True:
                stopped = stop.wait(every_s)
                failed = [a for a in started if a.failure]
                if failed:
                    why = "; ".join(f"node '{a.name}': {a.failure}" for a in failed)
                    raise NodeFailed(why)
                if stopped:
                    break
                watchdog.check()
                trimmer.check()
        except BaseException as exc:
            if not isinstance(exc, KeyboardInterrupt | NodeFailed):
                why = f"{type(exc).__name__}: {exc}"
            raise
        finally:
            watchdog.stopping(why)
            for adapter in reversed(started):
                adapter.stop()


def _joining(cfg: BusConfig) -> str:
    """How a session of ``cfg`` joins, for the supervisor's status line while it waits."""
    if cfg.mode == "client":
        return f"a client: waiting for a router at {', '.join(cfg.connect) or 'any address (multicast)'}"
    return f"{cfg.mode}" + (f", connecting to {', '.join(cfg.connect)}" if cfg.connect else "")


def _announce(bus: Bus, started: list[Adapter], restart: Restart) -> None:
    """A ``node`` event per node: this process is a supervisor's restart (and the log says so)."""
    log.warning("%s", restart)
    for adapter in started:
        event = {"t": time.time(), "kind": "node", "host": bus.host, "node": adapter.name, "adapter": adapter.kind,
                 "state": "restarted", "restarts": restart.count}
        if restart.previous:
            event["previous"] = restart.previous
        bus.put(keys.NODE_EVENTS, event)


def _located(adapter: Adapter, error: ConfigError) -> ConfigError:
    """A configuration error an adapter found only at start (``node 'x': key 'path': ...``),
    placed in its installation file (``show.toml [nodes.x] line 12: key 'path': ...``)."""
    found = re.search(r"key '([^']+)': (.*)", str(error))
    if adapter.where is None or found is None:
        return error
    return ConfigError(f"{adapter.where(found[1])}: key '{found[1]}': {found[2]}")
