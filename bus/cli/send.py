"""``sonibus send ROBOT VERB [ARG...]``: one command, its reply printed as JSON."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Any

from ... import schemas
from .. import keys
from ..client import owner_of, send_command, unreached
from ..commands import from_words
from ..errors import CommandError, ConfigError, RobotNotFound
from .api import Command, Environment, Exit, bus_config
from .hints import not_found, reach_hint, robots_hint, searching


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("robot", metavar="ROBOT")
    p.add_argument("verb", metavar="VERB", nargs="?", help=", ".join(schemas.command_verbs()))
    p.add_argument("args", nargs="*", metavar="ARG", help="NAME=VALUE, or the verb's main value")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the reply")


def command_args(verb: str, words: Sequence[str]) -> dict[str, Any]:
    """The request of ``NAME=VALUE`` words (and the verb's main value); a mistake is
    a usage error here, with the message OSC and JSON give for it."""
    verbs = schemas.command_verbs()
    if verb not in verbs:  # a typo, not the robot's refusal: said before the bus is joined
        raise ConfigError(f"unknown command '{verb}' — known commands: {', '.join(verbs)}")  # (the robot's words)
    try:
        return from_words(verb, words)
    except CommandError as exc:
        raise ConfigError(exc.message) from None


def _send(args: argparse.Namespace, env: Environment) -> Exit:
    if args.verb is None:  # argparse would ask for "VERB, ARG", though stop takes no ARG
        raise ConfigError(f"send {args.robot}: which command? One of {', '.join(schemas.command_verbs())}, "
                          f"e.g. sonibus send {args.robot} stop")
    request = command_args(args.verb, args.args)
    cfg = bus_config(args)
    # (a stop goes to every owner whatever the claims say: no waiting for the owner's claim, and
    # no settling once its owner's stop is known: an emergency's stop starts as soon as it can)
    stop = args.verb == "stop"
    with searching(cfg, args.robot, keys.command(args.robot, args.verb) if stop else "") as (bus, reached):
        owner = None if stop else owner_of(bus, args.robot, min(2.0, args.timeout))
        try:
            result = send_command(bus, args.robot, args.verb, request, timeout=args.timeout, owner=owner)
        except RobotNotFound:
            if stop:
                owner = owner_of(bus, args.robot, 0.5)  # (for the hint)
            if owner is not None:  # its token is here, its commands are not: refused on the way
                user = f" (user '{cfg.user}')" if cfg.user else ""
                raise CommandError("refused", f"robot '{args.robot}' is on the bus but nothing answered "
                                              f"'{args.verb}': access control on the robot's machine refuses "
                                              f"commands from this machine{user}") from None
            raise not_found(args.robot, robots_hint(bus, args.robot) if reached
                            else reach_hint(cfg, reached, "nothing found")) from None
    env.say(json.dumps(result))
    if unreached(result):  # (a stop is taken whatever the robot's state: its result says what came of it)
        env.hint(f"{args.verb} did not reach robot '{args.robot}' ({result.get('connection', '?')})"
                 + ("; its owner sends it as soon as the robot answers again" if result.get("pending") else ""))
        return Exit.TIMEOUT
    return Exit.OK


SEND = Command("send", "send a command to a robot, print the reply", _arguments, _send, bus=True)
