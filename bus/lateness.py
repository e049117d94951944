"""Why samples arrive late, in the words that fit where they came from.

A sink drops samples older than its ``max_age_ms`` rather than play them as a burst,
and says why it thinks they were late. On one machine no clock is to blame: the
robot's node and the sink share a clock, so a late sample means the machine was too
busy to run them in time (other programs, a replay at ×2, a node starting) or a node
paused. Between machines it is a link or node that stalled, or clocks out of step.
Where the robot's node runs comes from its owner's claim (``bus/ownership.py``):
call ``follow(bus)`` when the node starts, so the first warning knows it.
"""

from __future__ import annotations

from .claimwatch import owners
from .node import Bus
from .ownership import Claim


def follow(bus: Bus) -> None:
    """Start following the robots' owners on ``bus``'s session (cheap: one liveliness
    subscriber a session, shared with every other node that needs them)."""
    owners(bus)


def why_late(bus: Bus, robot: str) -> str:
    """Why ``robot``'s samples reach this node late: the likely causes, for where its node runs."""
    return because(owners(bus).owner(robot), bus.host)


def because(owner: Claim | None, host: str) -> str:
    """The likely causes of lateness, for a robot owned by ``owner`` seen from ``host``.

    >>> because(Claim("pepper", 1, "stage", "robot"), "stage")  # doctest: +ELLIPSIS
    "pepper's node (robot) runs on this machine too, so no clock is to blame: this machine was too busy..."
    >>> because(Claim("pepper", 1, "stage", "robot"), "sound-pc")  # doctest: +ELLIPSIS
    "pepper's node runs on stage: a link or node that stalled, or the clocks of stage and sound-pc not in step..."
    >>> because(None, "sound-pc")
    'a stalled publisher or link, or clocks not in step'
    """
    if owner is None:  # (a script's keys, or a robot whose claim has not been seen yet)
        return "a stalled publisher or link, or clocks not in step"
    if owner.host == host:
        return (f"{owner.robot}'s node ({owner.node}) runs on this machine too, so no clock is to blame: this "
                "machine was too busy to run both in time (its CPU), or a node paused")
    return (f"{owner.robot}'s node runs on {owner.host}: a link or node that stalled, or the clocks of "
            f"{owner.host} and {host} not in step (NTP: 'chronyc tracking' on both)")
