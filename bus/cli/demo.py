"""``sonibus demo``: the installation in ``adapters/demo.toml``, whose ``[demo]`` tables
say what the demo's flags are and which node options they set — the core knows none
of its adapters.

>>> sorted(wiring().flags), wiring().sets["sound.targets"]
(['host', 'port', 'rate', 'robot'], ['{host}:{port}'])
>>> filled(["{host}:{port}"], {"host": "127.0.0.1", "port": 9000}), filled("{rate}", {"rate": 50.0})
(['127.0.0.1:9000'], 50.0)
>>> blamed("demo.toml [nodes.robot]: key 'model': 'robbie' is unknown", {"robot": "robbie"})
"--robot robbie: model 'robbie' is unknown"
"""

from __future__ import annotations

import argparse
import contextlib
import re
import tomllib
from dataclasses import dataclass, replace
from functools import cache
from importlib import resources
from typing import Any

from .. import config, runner
from ..busconfig import BusConfig
from ..errors import ConfigError, OwnershipError
from ..node import Bus
from .api import DEMO_LISTEN, Command, Environment, Exit, add_bus_arguments, bus_config, on_loopback
from .run import stop_lines

WHERE = "demo.toml [demo]"


@dataclass(frozen=True)
class Flag:
    """``--NAME``: its default (whose type is the flag's) and its help."""

    default: str | int | float
    help: str


@dataclass(frozen=True)
class Wiring:
    """The ``[demo]`` tables: the flags, the options they set (``"node.option"`` →
    a template), the nodes ``--quiet`` leaves out, the lines said at start and the
    line said when the demo keeps to this machine."""

    flags: dict[str, Flag]
    sets: dict[str, Any]
    quiet_help: str
    leaves_out: tuple[str, ...]
    banner: tuple[str, ...]
    private: str


def _text() -> str:
    return resources.files("sonibus.adapters").joinpath("demo.toml").read_text(encoding="utf-8")


@cache
def wiring() -> Wiring:
    """What ``[demo]`` of demo.toml says, or ``ConfigError`` naming what is wrong there."""
    table = tomllib.loads(_text()).get("demo", {})
    try:
        flags = {name: Flag(spec["default"], spec["help"]) for name, spec in table["flags"].items()}
        quiet = table["quiet"]
        found = Wiring(flags, dict(table["sets"]), quiet["help"], tuple(quiet["leaves_out"]), tuple(table["banner"]),
                       str(table["private"]))
    except (KeyError, TypeError, AttributeError) as exc:
        raise ConfigError(f"{WHERE}: {type(exc).__name__}: {exc} — it needs flags, sets, quiet, banner and "
                          f"private, as the shipped demo.toml has them") from None
    for name, flag in flags.items():
        if not isinstance(flag.default, str | int | float) or isinstance(flag.default, bool):
            raise ConfigError(f"{WHERE}: flag '{name}': default {flag.default!r} must be a string or a number")
    return found


def filled(template: Any, values: dict[str, Any]) -> Any:
    """``template`` with ``{flag}`` replaced by the flags' values: a bare ``"{flag}"`` is
    the value itself (a number stays a number); lists are filled item by item."""
    if isinstance(template, list):
        return [filled(item, values) for item in template]
    if not isinstance(template, str):
        return template
    if template.startswith("{") and template.endswith("}") and template[1:-1] in values:
        return values[template[1:-1]]
    try:
        return template.format(**values)
    except (KeyError, IndexError, ValueError) as exc:
        raise ConfigError(f"{WHERE}: {template!r}: {type(exc).__name__} {exc} — known flags: "
                          f"{', '.join(values)}") from None


def _arguments(p: argparse.ArgumentParser) -> None:
    for name, flag in wiring().flags.items():
        shown = f"{flag.default:g}" if isinstance(flag.default, float) else flag.default
        p.add_argument(f"--{name}", dest=name, type=type(flag.default), default=flag.default,
                       help=f"{flag.help} (default: {shown})")
    p.add_argument("--quiet", action="store_true", help=wiring().quiet_help)
    add_bus_arguments(p, installation=False, demo=False)


def installation(values: dict[str, Any], quiet: bool = False) -> tuple[config.Installation, list[str] | None]:
    """demo.toml with the flags' ``values`` set, and the nodes to run (None: all)."""
    wired = wiring()
    found = config.parse(_text(), "demo.toml")
    for target, template in wired.sets.items():
        node, _, option = target.partition(".")
        if node not in found.nodes or not option:
            raise ConfigError(f"{WHERE}: sets '{target}': not NODE.OPTION of a node — nodes: "
                              f"{', '.join(found.nodes)}")
        found.nodes[node].options[option] = filled(template, values)
    return found, [name for name in found.nodes if name not in wired.leaves_out] if quiet else None


def _demo(args: argparse.Namespace, env: Environment) -> Exit:
    values = {name: getattr(args, name) for name in wiring().flags}
    wired, only = installation(values, args.quiet)
    try:
        adapters = runner.build(wired, only)
    except ConfigError as exc:  # a node option set by a flag: the flag is to blame, not demo.toml
        raise ConfigError(blamed(str(exc), values)) from None
    config = bus_config(args, wired.bus)
    for line in wiring().banner:
        env.say(filled(line, values))
    env.say(privacy(config))
    names = ", ".join(f"{a.name} ({a.kind})" for a in adapters)

    def started(bus: Bus) -> None:
        env.say(f"sonibus: running {names} on {bus.host}")

    try:
        try:
            runner.run(adapters, config, env.stop, on_started=started)
        except ConfigError as exc:
            if "Address already in use" not in str(exc) or args.listen or args.connect:
                raise
            # another demo of this machine listens there: join its bus (still this machine's only: listening
            # on loopback, not on Zenoh's default of every interface)
            env.say(f"  another demo runs on this machine ({', '.join(config.listen)}): joining its bus")
            runner.run(adapters, replace(config, listen=(DEMO_LISTEN,), connect=config.listen), env.stop,
                       on_started=started)
    except OwnershipError as exc:
        raise OwnershipError(blamed(str(exc), values, taken=True)) from None
    finally:
        with contextlib.suppress(OSError):  # (its output gone: nobody to tell)
            for line in stop_lines(adapters):
                env.say(line)
    return Exit.OK


def privacy(config: BusConfig) -> str:
    """The banner's line on who reaches the demo's bus: demo.toml's ``private`` line when
    it keeps to this machine (no multicast, every listen on loopback), else what does not.

    >>> privacy(BusConfig(multicast=False, listen=("tcp/127.0.0.1:7448",))) == wiring().private
    True
    >>> privacy(BusConfig(multicast=False, listen=("tcp/0.0.0.0:7448",)))
    '  NOT private: listening on tcp/0.0.0.0:7448 — other machines of your network can join this demo'
    """
    public = [e for e in config.listen if not on_loopback(e)] or ([] if config.listen else ["every interface"])
    if not public and not config.multicast:
        return wiring().private
    said = [f"listening on {', '.join(public)}"] if public else []
    said += ["multicast scouting on"] if config.multicast else []
    return f"  NOT private: {' and '.join(said)} — other machines of your network can join this demo"


def blamed(message: str, values: dict[str, Any], taken: bool = False) -> str:
    """``message`` in the words of the flag whose value it names: ``--robot robbie:
    model 'robbie' is unknown ...``; for a name already taken (``taken``), the flag
    that gives another. Messages that name no flag's value are kept."""
    for name, value in values.items():
        if f"'{value}'" not in message or (value == wiring().flags[name].default and not taken):
            continue
        if taken:
            return f"{message} — or run another: sonibus demo --{name} {value}2"
        problem = re.sub(r"^[^:]*\[nodes\.[^]]*\]: key '([^']*)': ", r"\1 ", message)
        return f"--{name} {value}: {problem}"
    return message


DEMO = Command("demo", "simulated robot → OSC, with a live view", _arguments, _demo)
