"""Zenoh sessions from a typed config: the one place that builds ``zenoh.Config``.

>>> cfg = BusConfig(mode="peer", multicast=False)
>>> with open_session(cfg) as session:
...     len(str(session.zid())) > 0
True
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import zenoh

from .errors import ConfigError
from .options import bad

MODES = ("peer", "client", "router")


@dataclass(frozen=True)
class BusConfig:
    """How a process joins the bus (the ``[bus]`` table of a configuration).

    ``options`` are raw Zenoh configuration entries (``{"transport/link/tx/lease": 2000}``)
    applied last, for everything sonibus does not name itself.
    """

    mode: str = "peer"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast: bool = True
    namespace: str = ""
    options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise bad("mode", f"'{self.mode}' is not one of {', '.join(MODES)}")

    def to_zenoh(self) -> zenoh.Config:
        config = zenoh.Config()
        entries: dict[str, Any] = {"mode": self.mode, "scouting/multicast/enabled": self.multicast}
        if self.connect:
            entries["connect/endpoints"] = list(self.connect)
        if self.listen:
            entries["listen/endpoints"] = list(self.listen)
        if self.namespace:
            entries["namespace"] = self.namespace
        entries.update(self.options)
        for key, value in entries.items():
            try:
                config.insert_json5(key, json.dumps(value))
            except Exception as exc:  # zenoh raises ZError with the parser's text
                raise ConfigError(f"bus option '{key}' = {json.dumps(value)} rejected by Zenoh: {exc}") from exc
        return config


def open_session(config: BusConfig) -> zenoh.Session:
    """Open a Zenoh session; the caller closes it (it is a context manager)."""
    try:
        return zenoh.open(config.to_zenoh())
    except ConfigError:
        raise
    except Exception as exc:
        raise ConfigError(f"cannot open the bus ({config.mode}, listen={list(config.listen)}, "
                          f"connect={list(config.connect)}): {exc}") from exc
