"""Why a one-shot command may have found nothing, and what to check."""

from __future__ import annotations

import difflib
from collections.abc import Sequence

from .. import keys
from ..node import Bus
from ..ownership import claims
from ..session import BusConfig


def reach_hint(cfg: BusConfig, reached: Sequence[str], what: str) -> str:
    """``what`` was found wanting: whom this command reached, and what to check."""
    where = (f"mode {cfg.mode}, multicast {'on' if cfg.multicast else 'off'}, "
             f"connect {', '.join(cfg.connect) or 'none'}, namespace '{cfg.namespace}'")
    if not reached:
        return (f"{what}: this command reached no peer or router ({where}) — is sonibus running on another "
                f"machine of this network? Give --connect tcp/<its address>:<port>, or --config FILE --host NAME "
                f"to join as a machine of the installation")
    return (f"{what}, though this command reached {len(reached)} peer(s)/router(s) ({where}) — check the "
            f"namespace (--namespace, or --config FILE --host NAME) and whether access control on the robot's "
            f"machine lets this machine's user see it")


def robots_hint(bus: Bus, robot: str) -> str:
    """The robots this session sees, and the likely one if ``robot`` is a typo."""
    seen = sorted(claims(bus.alive(keys.robot_token(), timeout=1.0)))
    if not seen:
        return "no robot is on the bus: start one (sonibus demo, or sonibus run with a robot node)"
    close = difflib.get_close_matches(robot, seen, n=1)
    return f"robots on the bus: {', '.join(seen)}" + (f" (did you mean '{close[0]}'?)" if close else "")
