"""Adapters by short name, from the ``sonibus.adapters`` entry-point group.

Built-in adapters are registered exactly like third-party ones (see
``pyproject.toml``); the core knows none of them by name.

>>> sorted(available())[:2]  # doctest: +SKIP
['console', 'osc']
"""

from __future__ import annotations

import dataclasses
import logging
from importlib.metadata import EntryPoint, entry_points

from .adapter import Adapter
from .errors import AdapterError

GROUP = "sonibus.adapters"

log = logging.getLogger(__name__)


def available() -> dict[str, EntryPoint]:
    """Installed adapters by name (not yet imported)."""
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def load(name: str) -> type[Adapter]:
    """The adapter class called ``name``, checked; ``AdapterError`` says what is wrong."""
    found = available()
    if name not in found:
        raise AdapterError(f"unknown adapter '{name}' — installed adapters: {', '.join(sorted(found)) or 'none'}")
    return _checked(found[name])


def load_all() -> dict[str, type[Adapter]]:
    """Every adapter that loads; a broken plug-in is logged and skipped."""
    loaded = {}
    for name, ep in sorted(available().items()):
        try:
            loaded[name] = _checked(ep)
        except AdapterError as exc:
            log.warning("%s (skipped)", exc)
    return loaded


def summary(cls: type[Adapter]) -> str:
    """The first line of an adapter's docstring."""
    return (cls.__doc__ or "").strip().splitlines()[0] if cls.__doc__ else ""


def _checked(ep: EntryPoint) -> type[Adapter]:
    where = f"adapter '{ep.name}' ({ep.value})"
    try:
        cls = ep.load()
    except Exception as exc:
        raise AdapterError(f"{where} cannot be imported: {type(exc).__name__}: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, Adapter)):
        raise AdapterError(f"{where} is not a subclass of sonibus.bus.Adapter")
    if not dataclasses.is_dataclass(cls.Config):
        raise AdapterError(f"{where}: its Config is not a dataclass")
    return cls
