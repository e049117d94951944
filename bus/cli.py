"""The ``sonibus`` command line. Parsing is separate from running, so the CLI
can be tested in-process: ``main(["send", "pepper", "stop"], env)``."""

from __future__ import annotations

import argparse
import contextlib
import enum
import json
import logging
import os
import re
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from importlib.metadata import entry_points
from typing import Any, TextIO

from .. import schemas
from . import codec, config, keys, ownership, registry, runner
from .client import owner_of, robot_info, send_command
from .errors import CommandError, ConfigError, RobotNotFound, SonibusError
from .node import Bus
from .presence import SILENCE_S
from .session import MODES, BusConfig, check_endpoint, check_option, discover, open_session

log = logging.getLogger(__name__)


class Exit(enum.IntEnum):
    """Exit statuses: 1 error, 2 usage or configuration (a bad flag, file, table or
    key), 3 robot not found, 4 command refused, 5 timeout, 130 interrupted (Ctrl-C,
    SIGTERM), 141 the output was closed (``sonibus info F | head -1``: quiet, as a Unix
    tool killed by SIGPIPE)."""

    OK = 0
    ERROR = 1
    USAGE = 2
    NOT_FOUND = 3
    REFUSED = 4
    TIMEOUT = 5
    INTERRUPTED = 130
    OUTPUT_CLOSED = 141


@dataclass
class Environment:
    """Where the CLI reads and writes; tests pass their own."""

    stdout: TextIO = field(default_factory=lambda: sys.stdout)
    stderr: TextIO = field(default_factory=lambda: sys.stderr)
    stop: threading.Event = field(default_factory=threading.Event)

    def say(self, text: str) -> None:
        """A line on stdout; ``BrokenPipeError`` once its reader went away (``_run`` ends quietly)."""
        print(text, file=self.stdout, flush=True)


@dataclass(frozen=True)
class Command:
    """A subcommand added by a package through the ``sonibus.commands`` entry-point
    group (``record = "sonibus.adapters.recorder.cli:RECORD"``): the core knows none by name.

    ``arguments`` adds its options to the subparser; ``run`` returns an exit status.
    With ``bus=True`` it also takes the bus options (read them with ``bus_config(args)``)."""

    name: str
    help: str
    arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace, Environment], int]
    bus: bool = False


COMMAND_GROUP = "sonibus.commands"


def plugin_commands(wanted: str | None = None) -> dict[str, Command]:
    """Installed subcommands by name — only ``wanted`` is imported if it is one of
    them, else all; a broken one is logged and skipped. An entry point's name is its
    command's name."""
    found = {}
    installed = entry_points(group=COMMAND_GROUP)
    if wanted not in installed.names:
        wanted = None
    for ep in installed:
        if wanted is not None and ep.name != wanted:
            continue
        try:
            command = ep.load()
        except Exception as exc:
            log.warning("command '%s' (%s) cannot be imported: %s: %s (skipped)", ep.name, ep.value,
                        type(exc).__name__, exc)
            continue
        if isinstance(command, Command):
            found[command.name] = command
        else:
            log.warning("command '%s' (%s) is not a sonibus.bus.cli.Command (skipped)", ep.name, ep.value)
    return found


def _command_word(argv: Sequence[str]) -> str | None:
    """The subcommand named in ``argv`` (the top-level options take no value)."""
    return next((word for word in argv if not word.startswith("-")), None)


# -- parsing -------------------------------------------------------------------------


def parser(extra: dict[str, Command] | None = None) -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="sonibus", description="Robots on a Zenoh bus, for sound tools.")
    top.add_argument("--traceback", action="store_true", help="show the full traceback of an error")
    top.add_argument("-v", "--verbose", action="count", default=0, help="log more (-vv: debug)")
    sub = top.add_subparsers(dest="command", required=True, metavar="COMMAND")

    bus_options = argparse.ArgumentParser(add_help=False)
    group = bus_options.add_argument_group("bus")
    group.add_argument("--mode", choices=MODES, help="Zenoh mode (default: peer)")
    group.add_argument("--connect", action="append", metavar="ENDPOINT", help="e.g. tcp/192.168.1.10:7447")
    group.add_argument("--listen", action="append", metavar="ENDPOINT", help="e.g. tcp/0.0.0.0:7447")
    group.add_argument("--no-multicast", action="store_true", help="do not discover peers by multicast")
    group.add_argument("--namespace", help="prefix that keeps this installation apart from others")
    group.add_argument("--zenoh", action="append", metavar="KEY=JSON", default=[],
                       help="raw Zenoh option, e.g. transport/link/tx/lease=2000")

    machine = argparse.ArgumentParser(add_help=False)
    group = machine.add_argument_group("installation")
    group.add_argument("--config", dest="bus_file", metavar="CONFIG.toml",
                       help="join the bus as the [bus] table of this installation file says")
    group.add_argument("--host", help="with --config: use its [bus.hosts.HOST] settings (default: this machine)")
    joins = [bus_options, machine]

    demo = sub.add_parser("demo", parents=[bus_options], help="simulated robot → OSC, with a live view")
    demo.add_argument("--robot", default="pepper", help="robot name: pepper, nao, pepper2... (default: pepper)")
    demo.add_argument("--port", type=int, default=9000, help="UDP port of the OSC receiver (default: 9000)")
    demo.add_argument("--host", default="127.0.0.1", help="host of the OSC receiver (default: 127.0.0.1)")
    demo.add_argument("--rate", type=float, default=100.0, help="frames per second (default: 100)")
    demo.add_argument("--quiet", action="store_true", help="no live view")

    run = sub.add_parser("run", parents=[bus_options], help="run the nodes of an installation file")
    run.add_argument("config", metavar="CONFIG.toml")
    run.add_argument("--only", nargs="+", metavar="NODE", help="run only these nodes")
    run.add_argument("--host", help="run the nodes of this host (default: this machine's name)")

    sub.add_parser("router", parents=joins, help="run a Zenoh router (joins subnets)")

    sub.add_parser("adapters", help="list installed adapters")

    nodes = sub.add_parser("nodes", parents=joins, help="list live nodes and robots")
    nodes.add_argument("--timeout", type=float, default=1.0, help="seconds to wait for answers")

    echo = sub.add_parser("echo", parents=joins, help="print samples as they arrive")
    echo.add_argument("keyexpr", metavar="KEYEXPR", help="e.g. 'pepper/joints/*' or '*/events/**'")
    echo.add_argument("--count", type=int, help="exit after this many samples")
    echo.add_argument("--duration", type=float, help="exit after this many seconds")

    send = sub.add_parser("send", parents=joins, help="send a command to a robot, print the reply")
    send.add_argument("robot", metavar="ROBOT")
    send.add_argument("verb", metavar="VERB", help=", ".join(schemas.command_verbs()))
    send.add_argument("args", nargs="*", metavar="ARG", help="NAME=VALUE, or the verb's main value")
    send.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the reply")

    for name, command in sorted((extra or {}).items()):
        if name in COMMANDS:
            log.warning("command '%s' from a plug-in is shadowed by the built-in one", name)
            continue
        command.arguments(sub.add_parser(name, parents=joins if command.bus else [], help=command.help))
    return top


def bus_config(args: argparse.Namespace, base: BusConfig | None = None) -> BusConfig:
    """``base`` (or the ``--config`` file's, or defaults) with the command-line bus options applied."""
    if base is None and getattr(args, "bus_file", None):
        base = config.load(args.bus_file).bus.for_host(args.host or socket.gethostname())
    cfg = base or BusConfig()
    changes: dict[str, Any] = {}
    if args.mode:
        changes["mode"] = args.mode
    for flag in ("connect", "listen"):
        for endpoint in getattr(args, flag) or ():
            try:
                check_endpoint(endpoint, listen=flag == "listen")
            except ValueError as exc:
                raise ConfigError(f"--{flag} {exc}") from None
        if getattr(args, flag):
            changes[flag] = tuple(getattr(args, flag))
    if args.no_multicast:
        changes["multicast"] = False
    if args.namespace is not None:
        changes["namespace"] = args.namespace
    if args.zenoh:
        options = dict(cfg.options)
        for item in args.zenoh:
            key, sep, value = item.partition("=")
            if not sep or not key:
                raise ConfigError(f"--zenoh '{item}' is not KEY=JSON, e.g. --zenoh transport/link/tx/lease=2000")
            try:
                options[key] = json.loads(value)
            except json.JSONDecodeError:
                options[key] = value  # a bare word: --zenoh mode=client
            try:
                check_option(key, options[key])
            except ValueError as exc:
                raise ConfigError(f"--zenoh '{item}': {exc}") from None
        changes["options"] = options
    try:
        return replace(cfg, **changes) if changes else cfg
    except ConfigError as exc:  # "key 'namespace': ..." from BusConfig: name the flag instead
        flags = {"namespace": "--namespace", "options": "--zenoh", "mode": "--mode"}
        raise ConfigError(re.sub(r"^key '(\w+)'", lambda m: flags.get(m[1], m[0]), str(exc))) from None


def command_args(verb: str, words: Sequence[str]) -> dict[str, Any]:
    """``NAME=VALUE`` words (and the verb's positional value) as typed arguments."""
    if verb not in schemas.command_verbs():
        return {}  # the robot answers with the list of verbs
    schema = schemas.command_schema(verb)
    props = schema.get("properties", {})
    named = [w for w in words if "=" in w.split(" ", 1)[0]]
    loose = [w for w in words if w not in named]
    args: dict[str, Any] = {}
    if loose:
        positional = schema.get("x-positional")
        if positional is None:
            raise ConfigError(f"{verb} takes only NAME=VALUE arguments: {', '.join(props) or 'none'}")
        if props[positional].get("type") != "string" and len(loose) > 1:
            raise ConfigError(f"{verb} takes one {positional}, got {' '.join(loose)!r}")
        args[positional] = _typed(verb, positional, props[positional], " ".join(loose))
    for word in named:
        name, _, value = word.partition("=")
        if name not in props:
            raise ConfigError(f"{verb} has no argument '{name}' — arguments: {', '.join(props) or 'none'}")
        args[name] = _typed(verb, name, props[name], value)
    return args


def _typed(verb: str, name: str, prop: dict[str, Any], text: str) -> Any:
    kind = prop.get("type")
    try:
        if kind == "array":
            items = [t for t in text.split(",") if t != ""]
            item_kind = prop.get("items", {}).get("type")
            return [float(t) if item_kind == "number" else t for t in items]
        if kind == "number":
            return float(text)
        if kind == "integer":
            return int(text)
        if kind == "boolean":
            lowered = text.lower()
            if lowered not in ("true", "false", "1", "0", "on", "off", "yes", "no"):
                raise ValueError(text)
            return lowered in ("true", "1", "on", "yes")
    except ValueError:
        what = {"array": "a list of numbers", "number": "a number", "integer": "an integer",
                "boolean": "true or false"}.get(kind, kind)
        raise ConfigError(f"{verb}: {name}={text!r} is not {what}") from None
    return text


# -- running -------------------------------------------------------------------------


def cmd_demo(args: argparse.Namespace, env: Environment) -> Exit:
    text = resources.files("sonibus.adapters").joinpath("demo.toml").read_text(encoding="utf-8")
    installation = config.parse(text, "demo.toml")
    specs = installation.nodes
    robot = specs["robot"]
    robot.options.update(robot=args.robot, rate_hz=args.rate)
    specs["sound"].options.update(targets=[f"{args.host}:{args.port}"])
    only = ["robot", "sound"] if args.quiet else None
    adapters = runner.build(installation, only)
    env.say(f"sonibus demo: simulated {args.robot} at {args.rate:g} frames/s → OSC to {args.host}:{args.port}, "
            f"one float per message at /{args.robot}/joints/<Joint>")
    env.say(f"  listen with: oscdump {args.port}     Ctrl-C to stop")
    runner.run(adapters, bus_config(args, installation.bus), env.stop)
    return Exit.OK


def cmd_run(args: argparse.Namespace, env: Environment) -> Exit:
    installation = config.load(args.config)
    host = args.host or socket.gethostname()
    adapters = runner.build(installation, args.only, host)
    names = ", ".join(f"{a.name} ({type(a).__name__})" for a in adapters)
    runner.run(adapters, bus_config(args, installation.bus.for_host(host)), env.stop,
               on_started=lambda bus: env.say(f"sonibus: running {names} on {bus.host}"), host=host)
    return Exit.OK


def cmd_router(args: argparse.Namespace, env: Environment) -> Exit:
    cfg = replace(bus_config(args), mode="router")
    if not cfg.listen:
        cfg = replace(cfg, listen=("tcp/0.0.0.0:7447",))
    with open_session(cfg) as session:
        env.say(f"sonibus router {session.zid()} listening on {', '.join(cfg.listen)}")
        while not env.stop.wait(0.25):
            pass
    return Exit.OK


def cmd_adapters(args: argparse.Namespace, env: Environment) -> Exit:
    for name, cls in registry.load_all().items():
        env.say(f"{name:<12} {registry.summary(cls)}")
    return Exit.OK


def cmd_nodes(args: argparse.Namespace, env: Environment) -> Exit:
    cfg = bus_config(args)
    with open_session(cfg) as session:
        bus = Bus(session)
        reached = discover(session)
        nodes = bus.alive(f"{keys.NODES}/**", timeout=args.timeout)
        robots = ownership.claims(bus.alive(keys.robot_token(), timeout=args.timeout))
        described = {(d.get("host"), d.get("node")): d for d in bus.query(f"{keys.NODES}/**", timeout=args.timeout)}
        now = time.time()
        env.say(f"{len(nodes)} node(s)")
        for key in nodes:
            host, _, node = key[len(keys.NODES) + 1:].partition("/")
            about = described.get((host, node), {})
            owns = f"  owns {', '.join(about['robots'])}" if about.get("robots") else ""
            since = f"  up {_duration(now - about['since'])}" if about.get("since") else ""
            state = about.get("state", "running")
            failed = f"  {state.upper()}: {about.get('failure', '')}" if state != "running" else ""
            env.say(f"  node  {node:<16} on {host:<12} {about.get('adapter', '?'):<12}{since}{owns}{failed}")
        env.say(f"{len(robots)} robot(s)")
        for name, claims in robots.items():
            info = robot_info(bus, name, timeout=args.timeout) or {}
            owner, standing_by = claims[0], claims[1:]
            conflict = "".join(f"  CONFLICT: {c.node} on {c.host} stands by" for c in standing_by)
            env.say(f"  robot {name:<16} {info.get('model', '?'):<8} {info.get('rate_hz', 0):g} frames/s  "
                    f"owned by {owner.node} on {owner.host}{conflict}")
        if not nodes:
            _hint(env, reach_hint(cfg, reached, "no node answered"))
    return Exit.OK


def reach_hint(cfg: BusConfig, reached: Sequence[str], what: str) -> str:
    """Why a one-shot command may have found nothing: whom it reached, and what to check."""
    where = (f"mode {cfg.mode}, multicast {'on' if cfg.multicast else 'off'}, "
             f"connect {', '.join(cfg.connect) or 'none'}, namespace '{cfg.namespace}'")
    if not reached:
        return (f"{what}: this command reached no peer or router ({where}) — is sonibus running on another "
                f"machine of this network? Give --connect tcp/<its address>:<port>, or --config FILE --host NAME "
                f"to join as a machine of the installation")
    return (f"{what}, though this command reached {len(reached)} peer(s)/router(s) ({where}) — check the "
            f"namespace (--namespace, or --config FILE --host NAME) and whether access control on the robot's "
            f"machine lets this machine's user see it")


def _hint(env: Environment, text: str) -> None:
    print(f"sonibus: hint: {text}", file=env.stderr, flush=True)


def _duration(seconds: float) -> str:
    """``3h02m``, ``4m10s``, ``12s``."""
    seconds = max(0, int(seconds))
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    return f"{seconds // 60}m{seconds % 60:02d}s" if seconds >= 60 else f"{seconds}s"


def cmd_echo(args: argparse.Namespace, env: Environment) -> Exit:
    deadline = time.monotonic() + args.duration if args.duration else None
    seen = 0
    cfg = bus_config(args)
    with open_session(cfg) as session:
        bus = Bus(session)
        subscriber, queue = bus.subscribe(args.keyexpr, 65536)
        hint_at = time.monotonic() + SILENCE_S
        try:
            while not env.stop.is_set() and (args.count is None or seen < args.count):
                if deadline is not None and time.monotonic() >= deadline:
                    break
                if not seen and time.monotonic() >= hint_at:  # said once, while it goes on waiting
                    _hint(env, _echo_hint(bus, cfg, args.keyexpr))
                    hint_at = float("inf")
                item = queue.get(timeout=0.2)
                if item is None:
                    continue
                key, payload = item
                try:
                    shown = json.dumps(codec.decode(payload), separators=(", ", ": "))
                except codec.DecodeError:
                    shown = repr(payload)
                env.say(f"{key} {shown}")
                seen += 1
            if not seen and hint_at < float("inf"):  # ended before the hint was due
                _hint(env, _echo_hint(bus, cfg, args.keyexpr))
        finally:
            subscriber.undeclare()
    return Exit.OK


def _echo_hint(bus: Bus, cfg: BusConfig, pattern: str) -> str:
    robots = list(ownership.claims(bus.alive(keys.robot_token(), timeout=0.5)))
    what = f"nothing matched '{pattern}'"
    if not robots:
        return reach_hint(cfg, discover(bus.session), f"{what} and no robot is on the bus")
    shown = ", ".join(robots[:8])
    example = robots[0]
    return (f"{what} — robots on the bus: {shown}; their keys: {example}/frame, {example}/joints/<Joint> "
            f"(HeadYaw, ...), {example}/events/<kind>, {example}/derived/<feature>/<name>: check the spelling, "
            f"or whether access control on the robot's machine lets this machine's user see them")


def cmd_send(args: argparse.Namespace, env: Environment) -> Exit:
    request = command_args(args.verb, args.args)
    cfg = bus_config(args)
    with open_session(cfg) as session:
        bus = Bus(session)
        reached = discover(session)
        owner = owner_of(bus, args.robot, min(2.0, args.timeout))  # not found after this: the command says so
        try:
            result = send_command(bus, args.robot, args.verb, request, timeout=args.timeout, owner=owner)
        except RobotNotFound as exc:
            if owner is not None:  # its token is here, its commands are not: refused on the way
                user = f" (user '{cfg.user}')" if cfg.user else ""
                raise CommandError("refused", f"robot '{args.robot}' is on the bus but nothing answered "
                                              f"'{args.verb}': access control on the robot's machine refuses "
                                              f"commands from this machine{user}") from None
            if not reached:
                exc.message = f"{exc.message} — {reach_hint(cfg, reached, 'nothing found')}"
                exc.args = (exc.message,)
            raise
    env.say(json.dumps(result))
    return Exit.OK


COMMANDS: dict[str, Callable[[argparse.Namespace, Environment], Exit]] = {
    "demo": cmd_demo, "run": cmd_run, "router": cmd_router, "adapters": cmd_adapters, "nodes": cmd_nodes,
    "echo": cmd_echo, "send": cmd_send,
}


def main(argv: Sequence[str] | None = None, env: Environment | None = None) -> int:
    env = env or Environment()
    argv = sys.argv[1:] if argv is None else list(argv)
    handler = logging.StreamHandler(env.stderr)
    handler.setFormatter(logging.Formatter("sonibus: %(levelname)s: %(message)s"))
    logger = logging.getLogger("sonibus")
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING)
    try:
        word = _command_word(argv)
        extra = {} if word in COMMANDS else plugin_commands(word)
        try:
            with contextlib.redirect_stdout(env.stdout), contextlib.redirect_stderr(env.stderr):
                args = parser(extra).parse_args(argv)
        except SystemExit as exc:  # argparse has printed its message
            return int(exc.code or 0)
        logger.setLevel((logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)])
        return _run(args, env, COMMANDS.get(args.command) or extra[args.command].run)
    finally:
        logger.removeHandler(handler)


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
        print(f"sonibus: error: {_one_line(exc)}", file=env.stderr, flush=True)
        return int(_status(exc))


def _status(exc: Exception) -> Exit:
    if isinstance(exc, RobotNotFound):
        return Exit.NOT_FOUND
    if isinstance(exc, CommandError):
        return Exit.TIMEOUT if exc.code == "timeout" else Exit.REFUSED
    if isinstance(exc, ConfigError):
        return Exit.USAGE
    return Exit.ERROR


def _one_line(exc: Exception) -> str:
    text = str(exc).strip() or type(exc).__name__
    if not isinstance(exc, SonibusError):
        text = f"{type(exc).__name__}: {text}"
    return " ".join(text.split())


def console_main() -> None:
    """Entry point of the ``sonibus`` script: Ctrl-C and SIGTERM end it cleanly."""
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
