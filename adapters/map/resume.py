"""``sonibus resume NODE [ROBOT]``: let a map node's maps drive their robots again after
a stop (docs/mapping.md, "Sound to movement"). A stop of a robot halts every map that
drives it until then: motion never comes back by itself."""

from __future__ import annotations

import argparse
import json
import threading

from sonibus.bus import keys
from sonibus.bus.cli.api import Command, Environment, Exit, bus_config, joined
from sonibus.bus.client import Outcome, ask_program
from sonibus.bus.errors import CommandError


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("node", metavar="NODE", help="the map node (its name in the installation file: moves)")
    p.add_argument("robot", metavar="ROBOT", nargs="?", default="", help="only this robot (default: all)")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the reply")


def _resume(args: argparse.Namespace, env: Environment) -> Exit:
    outcomes: list[Outcome] = []
    answered = threading.Event()
    with joined(bus_config(args)) as bus:
        bus.discover(keys.program(args.node, "resume"))  # (a new session: its peers' queryables known first)
        ask_program(bus, args.node, "resume", {"robot": args.robot} if args.robot else {},
                    lambda outcome: (outcomes.append(outcome), answered.set()), args.timeout)
        answered.wait(args.timeout + 1.0)
    if not outcomes:
        raise CommandError("timeout", f"map node '{args.node}' did not answer within {args.timeout:g} s")
    if isinstance(outcomes[0], CommandError):
        raise outcomes[0]
    env.say(json.dumps(outcomes[0]))
    return Exit.OK


RESUME = Command("resume", "let a map node's maps drive their robots again after a stop", _arguments, _resume,
                 bus=True)
