"""Adapters installed, by short name: the ``sonibus.adapters`` entry points, read
without importing any adapter (``registry`` loads and checks them). Apart from
the registry so that ``Adapter`` can name its own kind (``name_of``) without an
import circle: the registry imports the adapter base classes to check plug-ins.

>>> from sonibus.bus.adapter import Adapter
>>> name_of(Adapter)  # not registered: its class name
'Adapter'
"""

from __future__ import annotations

from importlib.metadata import EntryPoint, entry_points

__all__ = ["GROUP", "available", "entries", "name_of", "package"]

GROUP = "sonibus.adapters"


def entries() -> tuple[dict[str, EntryPoint], dict[str, str]]:
    """Installed adapters by name, and the names that more than one package
    registers, each with the one line that refuses it."""
    by_name: dict[str, list[EntryPoint]] = {}
    for ep in entry_points(group=GROUP):
        by_name.setdefault(ep.name, []).append(ep)
    unique = {name: eps[0] for name, eps in by_name.items() if len(eps) == 1}
    clashes = {name: f"adapter '{name}' is registered by more than one package: "
                     f"{' and '.join(f'{_package(ep)} ({ep.value})' for ep in eps)} — uninstall all but one"
               for name, eps in by_name.items() if len(eps) > 1}
    return unique, clashes


def available() -> dict[str, EntryPoint]:
    """Installed adapters by name (not yet imported); a name two packages register is left out."""
    return entries()[0]


def name_of(cls: type) -> str:
    """The name ``cls`` is registered under (found without importing any plug-in);
    its class name when it is not registered."""
    for name, ep in available().items():
        if ep.attr == cls.__name__ and (cls.__module__ + ".").startswith(ep.module + "."):
            return name
    return cls.__name__


def package(ep: EntryPoint) -> str:
    """The name of the distribution that registers ``ep`` ("?" if unknown)."""
    if ep.dist is None:
        return "?"
    # reading a distribution's name parses its METADATA file, about 1 ms; ``commands`` sorts
    # every command by it on every command line (60 ms a command): once per dist-info folder
    where = getattr(ep.dist, "_path", None)
    if where is None:
        return ep.dist.name
    key = str(where)
    if key not in _NAMES:
        _NAMES[key] = ep.dist.name
    return _NAMES[key]


_NAMES: dict[str, str] = {}  # dist-info folder → distribution name (the folders installed: a few dozen)


def _package(ep: EntryPoint) -> str:
    return f"package '{package(ep)}'" if ep.dist is not None else "an unknown package"
