"""Running nodes: build adapters from an installation, start them, stop them all."""

from __future__ import annotations

import contextlib
import logging
import re
import threading
from collections.abc import Callable

from . import registry
from .adapter import Adapter
from .config import Installation
from .errors import AdapterError, ConfigError, NodeFailed
from .messages import Limits
from .node import Bus
from .session import BusConfig, open_session

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
        adapters.append(spec.build(cls))
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
        on_started: Callable[[Bus], None] | None = None, host: str | None = None) -> None:
    """Open one session, start ``adapters`` in order, wait for ``stop``, stop them in
    reverse order and close the session — also on Ctrl-C or an error. ``host`` names
    this machine on the bus (default: its hostname). A node that fails (a worker
    died) stops them all too, and ``NodeFailed`` says which and why."""
    with contextlib.closing(open_session(bus_config, wait=True)) as session:
        bus = Bus(session, host=host, limits=Limits(max_future_s=bus_config.max_future_s))
        started: list[Adapter] = []
        try:
            for adapter in adapters:
                try:
                    adapter.start(bus)
                except ConfigError as exc:
                    raise _located(adapter, exc) from None
                started.append(adapter)
                log.info("started %r", adapter)
            if on_started is not None:
                on_started(bus)
            while not stop.wait(0.1):
                failed = [a for a in started if a.failure]
                if failed:
                    raise NodeFailed("; ".join(f"node '{a.name}': {a.failure}" for a in failed))
        finally:
            for adapter in reversed(started):
                adapter.stop()


def _located(adapter: Adapter, error: ConfigError) -> ConfigError:
    """A configuration error an adapter found only at start (``node 'x': key 'path': ...``),
    placed in its installation file (``show.toml [nodes.x] line 12: key 'path': ...``)."""
    found = re.search(r"key '([^']+)': (.*)", str(error))
    if adapter.where is None or found is None:
        return error
    return ConfigError(f"{adapter.where(found[1])}: key '{found[1]}': {found[2]}")
