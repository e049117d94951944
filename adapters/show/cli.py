"""``sonibus rehearse``: run an installation as ``sonibus run`` does, with the clock of
its show nodes running faster from a chosen time — a day in ten minutes.

    sonibus rehearse examples/museum.toml --from 09:50 --day 10m

Only the show's clock changes: opening hours, rests between gestures, the cap per
hour and pauses in scenarios pass faster; what the robot does (a behavior, a
sentence) takes its own time. On a real robot that means gestures much closer
together than on show days: rehearse with ``sim`` or ``naoqi-sim``, or slowly.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Callable

from sonibus.bus.adapter import Adapter
from sonibus.bus.cli.api import Command, Environment, Exit
from sonibus.bus.cli.run import run_arguments, run_installation
from sonibus.bus.errors import ConfigError

from . import Show
from .clock import speed_of, start


def _arguments(p: argparse.ArgumentParser) -> None:
    run_arguments(p)
    pace = p.add_mutually_exclusive_group()
    pace.add_argument("--day", default="10m", metavar="DURATION",
                      help="how long a day of the show lasts (10m, 90s, 1h; default 10m: 144× faster)")
    pace.add_argument("--speed", type=float, metavar="N", help="how many times faster the show's clock runs")
    p.add_argument("--from", dest="start", metavar="TIME",
                   help="the show's time to start from: HH:MM (today) or YYYY-MM-DD HH:MM, in the show's "
                        "time zone (default: now)")


def _rehearse(args: argparse.Namespace, env: Environment) -> Exit:
    try:
        speed = args.speed if args.speed is not None else speed_of(args.day)
        if not speed > 0:
            raise ValueError(f"--speed {speed:g} must be more than 0")
    except ValueError as exc:
        raise ConfigError(f"rehearse: {exc}") from None

    def prepare(adapters: list[Adapter]) -> None:
        shows = [a for a in adapters if isinstance(a, Show)]
        if not shows:
            raise ConfigError(f"{args.config}: no show node among {', '.join(a.name for a in adapters)} — "
                              "a rehearsal speeds up the clock of the show nodes (adapter = \"show\")")
        for show in shows:
            try:
                begins = start(args.start, show.config.zone) if args.start else None
                show.rehearse(speed, begins)
                show.on_change = _printer(env)
            except ValueError as exc:
                raise ConfigError(f"rehearse: --from: {exc}") from None
            env.say(f"sonibus: rehearsal: {show.name}'s clock runs {speed:g}× faster"
                    + (f" from {begins.isoformat(' ', 'seconds')}" if begins else ""))

    return run_installation(args, env, prepare)


def _printer(env: Environment) -> Callable[[str], None]:
    """Each opening and closing, with the show's clock, on stdout (a reader gone: the log still has it)."""
    def say(line: str) -> None:
        with contextlib.suppress(BrokenPipeError, ValueError):  # (stdout closed under a stopping rehearsal)
            env.say(f"sonibus: rehearsal: {line}")
    return say


REHEARSE = Command("rehearse", "run an installation with its show's clock faster (a day in minutes)",
                   _arguments, _rehearse)
