# PYTHON_ARGCOMPLETE_OK  (argcomplete's marker: this module answers shell completion)
"""``sonibus COMMAND``: every command, built-in or a plug-in's, is found in the
``sonibus.commands`` entry-point group; parsing is separate from running, so the
CLI can be tested in-process: ``main(["send", "pepper", "stop"], env)``."""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import os
import signal
import sys
from collections.abc import Callable, Sequence
from importlib.metadata import EntryPoint, entry_points, version

from .. import installed
from ..client import UNANSWERED
from ..errors import CommandError, ConfigError, OwnershipError, RobotNotFound, SonibusError
from ..text import PrintableFormatter
from .api import COMMAND_GROUP, Command, Environment, Exit, add_bus_arguments, line

log = logging.getLogger(__name__)

OWN = "sonibus"  # the distribution whose commands are listed first and never shadowed


def commands(wanted: str | None = None) -> dict[str, Command]:
    """Installed commands by name, sonibus's own first — only ``wanted`` is imported if
    it is one of them (and loads), else all; a broken one is logged and skipped, and of
    two with one name the first is kept (sonibus's own, if it is one of them) and the
    other named."""
    eps = sorted(entry_points(group=COMMAND_GROUP), key=lambda ep: installed.package(ep) != OWN)
    named = [ep for ep in eps if ep.name == wanted]
    found = _loaded(named)
    if not found:  # argparse's "invalid choice" lists the others
        found = _loaded([ep for ep in eps if ep not in named])
    return found


def _loaded(eps: list[EntryPoint]) -> dict[str, Command]:
    found: dict[str, Command] = {}
    origin: dict[str, str] = {}
    for ep in eps:
        if ep.name in found:
            log.warning("command '%s' of %s is also registered by %s, whose command is used (skipped)",
                        ep.name, installed.package(ep), origin[ep.name])
            continue
        command = _load(ep)
        if command is not None:
            found[ep.name] = command
            origin[ep.name] = installed.package(ep)
    own = [name for name in found if origin[name] == OWN]
    return {name: found[name] for name in own + sorted(set(found) - set(own))}


def _load(ep: EntryPoint) -> Command | None:
    try:
        command = ep.load()
    except Exception as exc:
        log.warning("command '%s' (%s) cannot be imported: %s: %s (skipped)", ep.name, ep.value,
                    type(exc).__name__, exc)
        return None
    if not isinstance(command, Command):
        log.warning("command '%s' (%s) is not a sonibus.bus.cli.Command (skipped)", ep.name, ep.value)
        return None
    if command.name != ep.name:
        log.warning("command '%s' (%s) calls itself '%s': an entry point's name is its command's (skipped)",
                    ep.name, ep.value, command.name)
        return None
    return command


def _command_word(argv: Sequence[str]) -> str | None:
    """The subcommand named in ``argv`` (the top-level options take no value)."""
    return next((word for word in argv if not word.startswith("-")), None)


def parser(found: dict[str, Command]) -> argparse.ArgumentParser:
    """The top-level parser, with a subparser for each command ``found``."""
    top = argparse.ArgumentParser(prog="sonibus", description="Robots on a Zenoh bus, for sound tools.")
    top.add_argument("--version", action="version", version=f"%(prog)s {version(OWN)}")
    top.add_argument("--traceback", action="store_true", help="show the full traceback of an error")
    top.add_argument("-v", "--verbose", action="count", default=0, help="log more (-vv: debug)")
    sub = top.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, command in found.items():
        try:  # on a parser of its own first: a command that cannot add its options is skipped, not fatal
            command.arguments(argparse.ArgumentParser(add_help=False))
        except Exception as exc:
            log.warning("command '%s' cannot add its options: %s: %s (skipped)", name, type(exc).__name__, exc)
            continue
        own = sub.add_parser(name, help=command.help)
        command.arguments(own)
        if command.bus:
            add_bus_arguments(own)
    return top


def main(argv: Sequence[str] | None = None, env: Environment | None = None) -> int:
    env = env or Environment()
    argv = sys.argv[1:] if argv is None else list(argv)
    handler = logging.StreamHandler(env.stderr)
    handler.setFormatter(PrintableFormatter("sonibus: %(levelname)s: %(message)s"))
    logger = logging.getLogger("sonibus")
    shown = _Shown(logging.WARNING)
    handler.addFilter(shown)
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING)
    try:
        found = commands(_command_word(argv))
        try:
            with contextlib.redirect_stdout(env.stdout), contextlib.redirect_stderr(env.stderr):
                args = parser(found).parse_args(argv)
        except SystemExit as exc:  # argparse has printed its message
            return int(exc.code or 0)
        level = (logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)]
        shown.level = level  # (stderr's own threshold: a log file may take more, bus/logfile.py)
        logger.setLevel(level)
        return _run(args, env, found[args.command].run)
    finally:
        logger.removeHandler(handler)


class _Shown(logging.Filter):
    """What stderr shows: records at its ``level`` (``-v``), and those of a logger that asks
    to be heard by a level of its own (naoqi's "connected to Pepper ..." line, said at the
    default level: a threshold on the handler alone hid it)."""

    def __init__(self, level: int) -> None:
        super().__init__()
        self.level = level

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= self.level:
            return True
        own = logging.getLogger(record.name).level
        return own != logging.NOTSET and record.levelno >= own


def _run(args: argparse.Namespace, env: Environment, run: Callable[[argparse.Namespace, Environment], int]) -> int:
    try:
        return int(run(args, env))
    except KeyboardInterrupt:
        return int(Exit.INTERRUPTED)
    except BrokenPipeError:  # whoever read our output is gone (| head): nothing to say, nobody to say it to
        return int(Exit.OUTPUT_CLOSED)
    except Exception as exc:
        if args.traceback:
            raise
        line(env.stderr, f"sonibus: error: {_one_line(exc)}")
        return int(_status(exc))


def _status(exc: Exception) -> Exit:
    if isinstance(exc, RobotNotFound):
        return Exit.NOT_FOUND
    if isinstance(exc, CommandError):
        return Exit.TIMEOUT if exc.code in UNANSWERED else Exit.REFUSED
    if isinstance(exc, ConfigError | OwnershipError):  # (a robot already owned: a second owner configured)
        return Exit.USAGE
    return Exit.ERROR


def _one_line(exc: Exception) -> str:
    text = str(exc).strip() or type(exc).__name__
    if not isinstance(exc, SonibusError):
        text = f"{type(exc).__name__}: {text}"
    return " ".join(text.split())


def complete() -> None:
    """Answer the shell's completion request and exit, when argcomplete's shell hook
    (``eval "$(register-python-argcomplete sonibus)"``) asked for one; else do nothing."""
    if "_ARGCOMPLETE" not in os.environ:
        return  # argcomplete and every command are imported only on a TAB: a normal run stays as fast
    import argcomplete

    with contextlib.redirect_stderr(io.StringIO()):  # a broken plug-in's warning must not land on the prompt
        top = parser(commands())
    argcomplete.autocomplete(top)


def console_main() -> None:
    """Entry point of the ``sonibus`` script: Ctrl-C and SIGTERM end it cleanly."""
    complete()
    env = Environment()

    def terminate(signum: int, frame: object) -> None:
        if not env.stop.is_set():  # the first signal unwinds; later ones must not cut the clean-up short
            env.stop.set()
            raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, terminate)
    signal.signal(signal.SIGINT, terminate)  # also when started in the background, where SIGINT is ignored
    status = main(sys.argv[1:], env)
    try:
        sys.stdout.flush()  # what is still buffered (argparse's --help) meets a closed pipe here, not at exit
    except BrokenPipeError:
        status = Exit.OUTPUT_CLOSED
    if status == Exit.OUTPUT_CLOSED:  # the rest goes nowhere, not into "Exception ignored" at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # as the Python docs on SIGPIPE say
    sys.exit(status)
