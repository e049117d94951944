"""What is there: ``sonibus adapters`` (installed), ``nodes`` (live nodes and
robots) and ``echo`` (samples as they arrive)."""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import zenoh

from .. import codec, connection, framing, health, keys, ownership, plan, registry
from ..busconfig import BusConfig
from ..client import robot_info
from ..errors import ConfigError
from ..node import Bus
from ..presence import SILENCE_S
from .api import Command, Environment, Exit, bus_config, joined
from .hints import no_demo, reach_hint, reach_hint_now


def _adapters(args: argparse.Namespace, env: Environment) -> Exit:
    lacking: dict[str, str] = {}
    listed = {name: registry.summary(cls) for name, cls in registry.load_all(lacking).items()}
    listed.update({name: f"(not installed: {install})" for name, install in lacking.items()})
    for name, summary in sorted(listed.items()):
        env.say(f"{name:<12} {summary}")
    return Exit.OK


ADAPTERS = Command("adapters", "list installed adapters", lambda p: None, _adapters)


# -- nodes ----------------------------------------------------------------------------


def _nodes_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--timeout", type=float, default=1.0, help="seconds to wait for answers")


def _nodes(args: argparse.Namespace, env: Environment) -> Exit:
    cfg = bus_config(args)
    with joined(cfg) as bus:
        reached = bus.discover()
        nodes = bus.alive(f"{keys.NODES}/**", timeout=args.timeout)
        robots = ownership.claims(bus.alive(keys.robot_token(), timeout=args.timeout))
        described = {(d.get("host"), d.get("node")): d for d in bus.query(f"{keys.NODES}/**", timeout=args.timeout)}
        stats = health.latest(bus, timeout=args.timeout)
        now = time.time()
        env.say(f"{len(nodes)} node(s)")
        for key in nodes:
            host, _, node = key[len(keys.NODES) + 1:].partition("/")
            env.say(node_line(host, node, described.get((host, node), {}), now))
            if (host, node) in stats:
                found = stats[(host, node)]
                env.say(f"        {found if isinstance(found, str) else health.summary(found)}")
        env.say(f"{len(robots)} robot(s)")
        for name, claims in robots.items():
            info = robot_info(bus, name, timeout=args.timeout)
            env.say(robot_line(name, info, claims))
        if not nodes:
            env.hint(reach_hint(cfg, reached, "no node answered"))
    return Exit.OK


def robot_line(name: str, info: dict[str, Any] | None, claims: list[ownership.Claim]) -> str:
    """One robot of ``sonibus nodes``: model, the frames per second its owner really
    publishes (0 when none), its connection state, its owner (and who stands by).

    >>> claim = ownership.Claim("pepper", 1, "laptop", "pepper")
    >>> print(robot_line("pepper", {"model": "pepper", "rate_hz": 50, "connection": {"state": "lost",
    ...       "error": "connect: Connection refused", "frames_per_s": 0.0}}, [claim]))  # doctest: +NORMALIZE_WHITESPACE
    robot pepper pepper 0 frames/s NOT CONNECTED: lost (connect: Connection refused) owned by pepper on laptop
    """
    owner, standing_by = claims[0], claims[1:]
    conflict = "".join(f"  CONFLICT: {c.node} on {c.host} stands by" for c in standing_by)
    state = connection.describe(connection.state_of(info)) if info is not None else "no info: its owner did not answer"
    model = (info or {}).get("model", "?")
    return (f"  robot {name:<16} {model:<8} {connection.rate(info):.0f} frames/s  {state}  "
            f"owned by {owner.node} on {owner.host}{conflict}")


def node_line(host: str, node: str, about: dict[str, Any], now: float) -> str:
    """One node of ``sonibus nodes``, from what it says of itself (``about``); columns
    go at the end of the line."""
    owns = f"  owns {', '.join(about['robots'])}" if about.get("robots") else ""
    since = f"  up {_duration(now - about['since'])}" if about.get("since") else ""
    state = about.get("state", "running")
    failed = f"  {state.upper()}: {about.get('failure', '')}" if state != "running" else ""
    controller = about.get("controller")  # a robot adapter that sends to a controller (ROS 2): matched or not
    if isinstance(controller, dict):
        failed += ("  controller matched" if controller.get("matched") is True
                   else f"  CONTROLLER NOT MATCHED: {str(controller.get('why', ''))[:200]}")
    return f"  node  {node:<16} on {host:<12} {about.get('adapter', '?'):<12}{since}{owns}{failed}"


def _duration(seconds: float) -> str:
    """``3h02m``, ``4m10s``, ``12s``.

    >>> _duration(10920), _duration(250), _duration(12)
    ('3h02m', '4m10s', '12s')
    """
    seconds = max(0, int(seconds))
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    return f"{seconds // 60}m{seconds % 60:02d}s" if seconds >= 60 else f"{seconds}s"


NODES = Command("nodes", "list live nodes and robots", _nodes_arguments, _nodes, bus=True)


# -- echo -----------------------------------------------------------------------------


def _echo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("keyexpr", metavar="KEYEXPR", help="e.g. 'pepper/joints/*' or '*/events/**'")
    p.add_argument("--count", type=int, help="exit after this many samples")
    p.add_argument("--duration", type=float, help="exit after this many seconds")
    p.add_argument("--timeout", type=float, metavar="S",
                   help="exit with status 5 (timeout) once S seconds passed without a sample (default: wait)")


def _echo(args: argparse.Namespace, env: Environment) -> Exit:
    if args.timeout is not None and not args.timeout > 0:
        raise ConfigError(f"--timeout {args.timeout:g}: give the seconds to wait for a sample, e.g. --timeout 5")
    deadline = time.monotonic() + args.duration if args.duration else None
    seen = 0
    cfg = bus_config(args)
    missing = no_demo(cfg)
    if missing:  # said at once (known in a millisecond); it waits on, and joins the demo once it runs
        env.hint(f"{missing}; echo waits for it")
    with joined(cfg) as bus:
        # derived values come in derived frames (<robot>/derived): shown as each value's own key, as before
        frames = plan.plan([args.keyexpr]).derived
        subscriber, queue = bus.subscribe(args.keyexpr, 65536, skip=keys.is_derived_frame if frames else None)
        others = [bus.subscribe(k, queue=queue)[0] for k in frames]
        wanted = zenoh.KeyExpr(keys.expr(args.keyexpr))
        hint_at = float("inf") if missing else time.monotonic() + SILENCE_S
        last = time.monotonic()  # (the last sample, or the start)
        try:
            while not env.stop.is_set() and (args.count is None or seen < args.count):
                if deadline is not None and time.monotonic() >= deadline:
                    break
                if args.timeout is not None and time.monotonic() - last >= args.timeout:
                    what = "no sample" if not seen else f"no sample after the {seen} shown"
                    print(f"sonibus: error: echo '{args.keyexpr}': {what} for {args.timeout:g} s",
                          file=env.stderr, flush=True)
                    if not seen and hint_at < float("inf"):
                        env.hint(_echo_hint(bus, cfg, args.keyexpr))
                    return Exit.TIMEOUT
                if not seen and time.monotonic() >= hint_at:  # said once, while it goes on waiting
                    env.hint(_echo_hint(bus, cfg, args.keyexpr))
                    hint_at = float("inf")
                item = queue.get(timeout=0.2 if args.timeout is None else min(0.2, args.timeout))
                if item is None:
                    continue
                key, payload = item
                last = time.monotonic()
                for line in _lines(key, payload, wanted if frames else None):
                    if args.count is not None and seen >= args.count:
                        break
                    env.say(line)
                    seen += 1
            if not seen and hint_at < float("inf"):  # ended before the hint was due
                env.hint(_echo_hint(bus, cfg, args.keyexpr))
        finally:
            for each in (subscriber, *others):
                each.undeclare()
    return Exit.OK


def _lines(key: str, payload: bytes, derived: zenoh.KeyExpr | None) -> list[str]:
    """What ``echo`` prints of a sample: ``key message``; a derived frame, when ``derived`` (the
    pattern) asked for derived values, as the value of each key it selects (``key sample``)."""
    try:
        message = codec.decode(payload)
    except codec.DecodeError:
        return [f"{key} {payload!r}"]
    if derived is None or not keys.is_derived_frame(key):
        return [f"{key} {json.dumps(message, separators=(', ', ': '), default=_unprintable)}"]
    try:
        return [f"{key}/{name} {json.dumps(sample, separators=(', ', ': '), default=_unprintable)}"
                for name, sample in framing.derived_samples(message)
                if derived.intersects(zenoh.KeyExpr(f"{key}/{name}"))]
    except (KeyError, TypeError, ValueError, zenoh.ZError):  # (not a derived frame, or a bad name: as it is)
        return [f"{key} {json.dumps(message, separators=(', ', ': '), default=_unprintable)}"]


def _unprintable(value: object) -> str:
    """What JSON cannot show: audio's PCM (``"<640 bytes>"``) and anything else by its type."""
    return f"<{len(value)} bytes>" if isinstance(value, bytes | bytearray) else f"<{type(value).__name__}>"


def _echo_hint(bus: Bus, cfg: BusConfig, pattern: str) -> str:
    robots = list(ownership.claims(bus.alive(keys.robot_token(), timeout=0.5)))
    what = f"nothing matched '{pattern}'"
    if not robots:
        return reach_hint_now(cfg, bus, f"{what} and no robot is on the bus")
    shown = ", ".join(robots[:8])
    example = robots[0]
    return (f"{what} — robots on the bus: {shown}; their keys: {example}/frame, {example}/joints/<Joint> "
            f"(HeadYaw, ...), {example}/events/<kind>, {example}/derived/<feature>/<name>: check the spelling, "
            f"or whether access control on the robot's machine lets this machine's user see them")


ECHO = Command("echo", "print samples as they arrive", _echo_arguments, _echo, bus=True)
