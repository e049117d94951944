"""Why a one-shot command may have found nothing, and what to check."""

from __future__ import annotations

import contextlib
import difflib
import socket
from collections.abc import Iterator, Sequence

from .. import keys
from ..busconfig import BusConfig
from ..errors import RobotNotFound
from ..node import Bus
from ..ownership import claims
from .api import DEMO_BUS, joined

PROBE_S = 0.5  # a connect to loopback is answered in a millisecond, or refused in less


def demo_running() -> bool:
    """Whether this machine's ``sonibus demo`` runs: something accepts a connection at
    its fixed loopback port (``DEMO_BUS``), where ``--demo`` connects. Known in a
    millisecond, without joining or scouting; this network namespace's demo only,
    which is the one ``--demo`` can reach."""
    host, _, port = DEMO_BUS.partition("/")[2].rpartition(":")
    try:
        with socket.create_connection((host, int(port)), timeout=PROBE_S):
            return True
    except OSError:
        return False


def joins_demo(cfg: BusConfig) -> bool:
    """Whether ``cfg`` joins this machine's demo (``--demo``)."""
    return DEMO_BUS in cfg.connect


def no_demo(cfg: BusConfig) -> str:
    """With ``--demo``, when no demo runs on this machine: that, and the fix ("" otherwise).
    Said before joining: nothing else can answer there."""
    if not joins_demo(cfg) or demo_running():
        return ""
    return (f"no demo is running on this machine (nothing listens at {DEMO_BUS}, where --demo joins it) — "
            f"start one in another terminal: make demo (or sonibus demo)")


def demo_missed(cfg: BusConfig, reached: Sequence[str]) -> bool:
    """Whether a command without ``--demo`` found nobody while this machine's demo runs
    (a demo keeps off the network: scouting never finds it, only ``--demo`` joins it)."""
    return not reached and not cfg.connect and demo_running()


def reach_hint(cfg: BusConfig, reached: Sequence[str], what: str) -> str:
    """``what`` was found wanting: whom this command reached, and what to check."""
    where = (f"mode {cfg.mode}, multicast {'on' if cfg.multicast else 'off'}, "
             f"connect {', '.join(cfg.connect) or 'none'}, namespace '{cfg.namespace}'")
    if not reached:
        missing = no_demo(cfg)
        if missing:
            return f"{what}: {missing}"
        if demo_missed(cfg, reached):
            return (f"{what}: this command reached no peer or router ({where}), and a demo runs on this machine: "
                    f"add --demo to join it (a demo keeps off the network: only --demo reaches it)")
        demo = "" if cfg.connect else "; or start a demo on this machine (make demo) and add --demo"
        return (f"{what}: this command reached no peer or router ({where}) — is sonibus running on another "
                f"machine of this network? Give --connect tcp/<its address>:<port>, or --config FILE --host NAME "
                f"to join as a machine of the installation{demo}")
    return (f"{what}, though this command reached {len(reached)} peer(s)/router(s) ({where}) — check the "
            f"namespace (--namespace, or --config FILE --host NAME) and whether access control on the robot's "
            f"machine lets this machine's user see it")


def reach_hint_now(cfg: BusConfig, bus: Bus, what: str) -> str:
    """``reach_hint`` with whom ``bus`` reaches (``Bus.discover``: up to 2 s with nobody
    to find), not waited for when the missing demo says it all."""
    missing = no_demo(cfg)
    return f"{what}: {missing}" if missing else reach_hint(cfg, bus.discover(), what)


def robots_hint(bus: Bus, robot: str) -> str:
    """The robots this session sees, and the likely one if ``robot`` is a typo."""
    seen = sorted(claims(bus.alive(keys.robot_token(), timeout=1.0)))
    if not seen:
        return "no robot is on the bus: start one (sonibus demo, or sonibus run with a robot node)"
    close = difflib.get_close_matches(robot, seen, n=1)
    return f"robots on the bus: {', '.join(seen)}" + (f" (did you mean '{close[0]}'?)" if close else "")


def not_found(robot: str, why: str, message: str = "") -> RobotNotFound:
    """``RobotNotFound`` for ``robot`` (its ``message``, or the usual one), with ``why``
    and what to check."""
    missing = RobotNotFound(robot)
    missing.message = f"{message or missing.message} — {why}"
    missing.args = (missing.message,)
    return missing


@contextlib.contextmanager
def searching(cfg: BusConfig, robot: str, served: str = "") -> Iterator[tuple[Bus, list[str]]]:
    """``joined(cfg)`` for a command that looks for ``robot``, with whom it reached
    (``Bus.discover``, with ``served``: a stop's key); ``RobotNotFound`` at once when the demo is what is missing: with
    ``--demo`` and no demo running (before joining), or nobody reached by scouting while
    this machine's demo runs (it needs ``--demo``)."""
    missing = no_demo(cfg)
    if missing:
        raise not_found(robot, missing)
    with joined(cfg) as bus:
        reached = bus.discover(served)
        if demo_missed(cfg, reached):
            raise not_found(robot, reach_hint(cfg, reached, "nothing found"))
        yield bus, reached
