"""``sonibus resume NODE [ROBOT]``: let a map node's maps drive their robots again after
a stop (docs/mapping.md, "Sound to movement"). A stop of a robot halts every map that
drives it until then: motion never comes back by itself."""

from __future__ import annotations

import argparse
import json
import threading
from collections.abc import Callable
from typing import Any

from sonibus.bus import keys
from sonibus.bus.cli.api import Command, Environment, Exit, bus_config, joined
from sonibus.bus.client import Outcome, ask_program
from sonibus.bus.errors import CommandError
from sonibus.bus.node import Bus


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("node", metavar="NODE", help="the map node (its name in the installation file: moves)")
    p.add_argument("robot", metavar="ROBOT", nargs="?", default="", help="only this robot (default: all)")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the reply")


def _resume(args: argparse.Namespace, env: Environment) -> Exit:
    def send(bus: Bus, done: Callable[[Outcome], None]) -> None:
        ask_program(bus, args.node, "resume", {"robot": args.robot} if args.robot else {}, done, args.timeout)
    env.say(json.dumps(asked(args, keys.program(args.node, "resume"), args.node, send)))
    return Exit.OK


def asked(args: argparse.Namespace, key: str, node: str, send: Callable[[Bus, Callable[[Outcome], None]], None]) -> Any:
    """The result of one request to map node ``node`` on ``key``, sent by ``send(bus, done)`` from a
    session of its own (``args``: the bus options, ``timeout``); ``CommandError`` when refused or
    unanswered."""
    outcomes: list[Outcome] = []
    answered = threading.Event()
    with joined(bus_config(args)) as bus:
        bus.discover(key)  # (a new session: its peers' queryables known first)
        send(bus, lambda outcome: (outcomes.append(outcome), answered.set()))
        answered.wait(args.timeout + 1.0)
    if not outcomes:
        raise CommandError("timeout", f"map node '{node}' did not answer within {args.timeout:g} s")
    if isinstance(outcomes[0], CommandError):
        raise outcomes[0]
    return outcomes[0]


RESUME = Command("resume", "let a map node's maps drive their robots again after a stop", _arguments, _resume,
                 bus=True)
