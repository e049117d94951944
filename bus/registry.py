"""Adapters by short name, from the ``sonibus.adapters`` entry-point group.

Built-in adapters are registered exactly like third-party ones (see
``pyproject.toml``); the core knows none of them by name. Each is checked when
it loads, before any node starts: a robot adapter's ``Verbs`` must implement
every verb (``verbs.RobotVerbs``), and a name two packages register is refused.

>>> sorted(entries()[0])[:2]  # doctest: +SKIP
['console', 'osc']
"""

from __future__ import annotations

import dataclasses
import json
import logging
import re
import urllib.parse
from importlib.metadata import EntryPoint, entry_points

from .adapter import Adapter
from .errors import AdapterError
from .installed import GROUP, _package, entries, package
from .owner import RobotAdapter
from .verbs import missing

log = logging.getLogger(__name__)


def load(name: str) -> type[Adapter]:
    """The adapter class called ``name``, checked; ``AdapterError`` says what is wrong."""
    found, clashes = entries()
    if name in clashes:
        raise AdapterError(clashes[name])
    if name not in found:
        raise AdapterError(f"unknown adapter '{name}' — installed adapters: {', '.join(sorted(found)) or 'none'}")
    return _checked(found[name])


def load_all(lacking: dict[str, str] | None = None) -> dict[str, type[Adapter]]:
    """Every adapter that loads; a broken plug-in, or a name two packages register, is
    logged and skipped. One whose optional dependencies are not installed (the ``naoqi``
    extra) is no fault: it goes into ``lacking``, name → what to install, unlogged."""
    found, clashes = entries()
    for message in clashes.values():
        log.warning("%s (skipped)", message)
    loaded = {}
    for name, ep in sorted(found.items()):
        try:
            loaded[name] = _checked(ep)
        except MissingExtra as exc:
            if lacking is not None:
                lacking[name] = exc.install
        except AdapterError as exc:
            log.warning("%s (skipped)", exc)
    return loaded


def summary(cls: type[Adapter]) -> str:
    """The first line of an adapter's docstring."""
    return (cls.__doc__ or "").strip().splitlines()[0] if cls.__doc__ else ""


class MissingExtra(AdapterError):
    """An adapter needs optional dependencies that are not installed; ``install`` says which."""

    def __init__(self, message: str, install: str) -> None:
        super().__init__(message)
        self.install = install


def install_line(ep: EntryPoint, extra: str) -> str:
    """How to add ``extra`` to ``ep``'s distribution as it was installed: from a clone
    (``pip install -e '/path/to/clone[naoqi]'``), a wheel or source file, or an index
    (sonibus itself is not on PyPI: its name alone would point nowhere)."""
    try:
        origin = json.loads(ep.dist.read_text("direct_url.json") or "null") if ep.dist is not None else None
    except ValueError:
        origin = None
    url = urllib.parse.urlparse(origin.get("url", "")) if isinstance(origin, dict) else None
    if url is None or url.scheme != "file":
        return f"pip install '{package(ep)}[{extra}]'"
    editable = "-e " if (origin.get("dir_info") or {}).get("editable") else ""
    return f"pip install {editable}'{urllib.parse.unquote(url.path)}[{extra}]'"


def install_extra(extra: str, adapter: str = "sim") -> str:
    """How to add sonibus's own ``extra`` as sonibus was installed (the line of
    ``install_line``), for an adapter that needs it only once it runs (``ros2``'s DDS);
    ``adapter`` names one of sonibus's entry points to find its distribution by."""
    found = [ep for ep in entry_points(group=GROUP) if ep.name == adapter]
    return install_line(found[0], extra) if found else f"pip install -e '.[{extra}]' (in sonibus's clone)"


def extra_of(ep: EntryPoint, module: str) -> str | None:
    """The extra of ``ep``'s distribution that installs ``module`` (``qi`` → ``naoqi``)."""
    for requirement in (ep.dist.requires or ()) if ep.dist is not None else ():
        name, _, marker = requirement.partition(";")
        extra = re.search(r"extra\s*==\s*['\"]([^'\"]+)['\"]", marker)
        project = re.split(r"[\s<>=!~\[(]", name.strip())[0].replace("-", "_").lower()
        # a project installs its module under its name or its first word (JACK-Client: jack, foxglove-sdk: foxglove)
        if extra and module.lower() in (project, project.partition("_")[0]):
            return extra.group(1)
    return None


def _checked(ep: EntryPoint) -> type[Adapter]:
    where = f"adapter '{ep.name}' ({ep.value}, {_package(ep)})"
    try:
        cls = ep.load()
    except ModuleNotFoundError as exc:
        extra = extra_of(ep, (exc.name or "").partition(".")[0])
        if extra is None:
            raise AdapterError(f"{where} cannot be imported: {type(exc).__name__}: {exc}") from exc
        install = install_line(ep, extra)
        raise MissingExtra(f"adapter '{ep.name}' needs the optional '{extra}' dependencies ({exc.name}): "
                           f"{install}", install) from None
    except Exception as exc:
        raise AdapterError(f"{where} cannot be imported: {type(exc).__name__}: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, Adapter)):
        raise AdapterError(f"{where} is not a subclass of sonibus.bus.Adapter")
    if not dataclasses.is_dataclass(cls.Config):
        raise AdapterError(f"{where}: its Config is not a dataclass")
    if issubclass(cls, RobotAdapter):
        _check_verbs(cls, where)
    return cls


def _check_verbs(cls: type[RobotAdapter], where: str) -> None:
    verbs = getattr(cls, "Verbs", None)
    if not isinstance(verbs, type):
        raise AdapterError(f"{where} names no Verbs class — set Verbs to the class of what its _open() sets "
                           f"as self.verbs (docs/adapters.md)")
    if lacking := missing(verbs):
        raise AdapterError(f"{where}: its Verbs class {verbs.__name__} does not implement {', '.join(lacking)} "
                           f"— implement every verb of sonibus.bus.verbs.RobotVerbs (docs/adapters.md)")
