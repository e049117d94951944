"""Test-only guard: no Zenoh multicast scouting from this machine's own network, only from
the network namespaces the tests make (``tests/net/netns.py``).

``tests/conftest.py`` puts this folder on ``PYTHONPATH`` and names its network namespace in
``SONIBUS_TEST_NETNS``, so every Python process the tests start (``sonibus run``, ``demo``,
``send``; a wheel's own interpreter) imports this module at start-up. Once a process imports
``zenoh``, ``zenoh.open`` with multicast scouting on (Zenoh's default) and ``zenoh.scout``
raise in a process of that namespace: a test that forgot ``--no-multicast`` or ``multicast =
false`` fails, naming the fix, instead of scouting the LAN it runs on. A process started in a
namespace of the tests' own (``ip netns exec``) is in another namespace, and scouts freely.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import os
import sys
from typing import Any

REFUSED = ("multicast scouting from the machine's own network (the test suite sends nothing off loopback): "
           "give --no-multicast, multicast = false or BusConfig(multicast=False), or run it in a network "
           "namespace (tests/net/netns.py)")
LIBMAPPER_REFUSED = ("libmapper discovers by multicast on the machine's own network (the test suite sends nothing "
                     "off loopback): run it in a network namespace (tests/net/netns.py, tests/libmapper)")


def _in_root_namespace() -> bool:
    root = os.environ.get("SONIBUS_TEST_NETNS")
    try:
        return bool(root) and os.readlink("/proc/self/ns/net") == root
    except OSError:
        return False


def guard(zenoh: Any) -> None:
    """Wrap ``zenoh.open`` and ``zenoh.scout`` (once)."""
    if getattr(zenoh, "_sonibus_guarded", False):
        return
    opener, scouter = zenoh.open, zenoh.scout

    def open(config: Any, *args: Any, **kwargs: Any) -> Any:
        if _in_root_namespace() and config.get_json("scouting/multicast/enabled") != "false":
            raise RuntimeError(f"zenoh.open: {REFUSED}")
        return opener(config, *args, **kwargs)

    def scout(*args: Any, **kwargs: Any) -> Any:
        if _in_root_namespace():
            raise RuntimeError(f"zenoh.scout: {REFUSED}")
        return scouter(*args, **kwargs)

    zenoh.open, zenoh.scout, zenoh._sonibus_guarded = open, scout, True


def guard_libmapper(libmapper: Any) -> None:
    """Refuse a libmapper ``Graph`` or ``Device`` (each joins libmapper's multicast bus) in
    this machine's own namespace (once)."""
    if getattr(libmapper, "_sonibus_guarded", False):
        return
    for cls in (libmapper.Graph, libmapper.Device):
        def init(self: Any, *args: Any, _init: Any = cls.__init__, _name: str = cls.__name__, **kwargs: Any) -> None:
            if _in_root_namespace() and not (kwargs.get("ptr") or (args and isinstance(args[0], int))):
                raise RuntimeError(f"libmapper.{_name}: {LIBMAPPER_REFUSED}")
            _init(self, *args, **kwargs)
        cls.__init__ = init
    libmapper._sonibus_guarded = True


GUARDS = {"zenoh": guard, "libmapper": guard_libmapper}


class _OnImport(importlib.abc.MetaPathFinder):
    """Guards ``zenoh`` and ``libmapper`` right after they are imported (importing them here
    would slow every process)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def find_spec(self, name: str, path: Any, target: Any = None) -> Any:
        if name != self.name:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        run = spec.loader.exec_module

        def exec_module(module: Any) -> None:
            run(module)
            GUARDS[name](module)
        spec.loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec


if os.environ.get("SONIBUS_TEST_NETNS"):
    for _name, _guard in GUARDS.items():
        if _name in sys.modules:
            _guard(sys.modules[_name])
        else:
            sys.meta_path.insert(0, _OnImport(_name))
