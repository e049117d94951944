"""Joint targets from libmapper inputs to a real robot owner (a sim on a real Zenoh
session): rate-capped, latest wins, NaN/inf never sent, past-the-limits refused by
the owner and said (``adapters/libmapper/commands.py``; no libmapper needed here)."""

from __future__ import annotations

import time
from collections import Counter

from sonibus.adapters.libmapper.commands import Commands

from ..conftest import wait_for


def test_a_flood_of_targets_becomes_at_most_hz_commands_and_the_latest_is_reached(net):
    sim = net.sim("pepper")
    bus = net.bus("mapper")
    _, events = bus.subscribe("pepper/events/command")
    counts: Counter[str] = Counter()
    said: list[str] = []
    commands = Commands(bus, 10.0, 1.0, 2.0, lambda k: counts.update([k]),
                        lambda kind, text: said.append(text))
    # (one command first, until its event comes: the events' subscription reached the owner, none is missed)
    commands.take("pepper", "HipRoll", 0.0)
    wait_for(lambda: commands.flush() or events.drain(timeout=0.1), 10, "the first command's event")
    wait_for(lambda: commands.flush() or commands.idle, 5, "the first command answered")
    events.drain(timeout=0.2)
    counts.clear()
    started = time.monotonic()
    for i in range(1, 201):  # 200 targets in about a second, as a map from a fast fader sends them
        commands.take("pepper", "HipRoll", 0.4 * i / 200)
        commands.flush()
        time.sleep(0.005)
    took = time.monotonic() - started
    wait_for(lambda: commands.flush() or commands.idle, 5, "the last target to be sent and answered")
    sent = counts["commands"]
    assert counts["inputs"] == 200 and counts["commands_refused"] == 0, counts
    assert 2 <= sent <= took * 10 + 2, f"{sent} commands in {took:.2f} s at command_hz 10"
    wait_for(lambda: abs(sim.body.pose()["HipRoll"] - 0.4) < 0.01, 5, "HipRoll at the latest target, 0.4",
             lambda: str(sim.body.pose()["HipRoll"]))
    assert len(events.drain(timeout=0.5)) == sent  # (what the owner answered: nothing more left)


def test_nan_and_inf_are_refused_here_and_a_target_past_the_limits_by_the_owner(net):
    sim = net.sim("pepper")
    bus = net.bus("mapper")
    counts: Counter[str] = Counter()
    said: list[str] = []
    commands = Commands(bus, 20.0, 0.3, 2.0, lambda k: counts.update([k]), lambda kind, text: said.append(text))
    for value in (float("nan"), float("inf"), float("-inf"), [float("nan")], "3", True):
        commands.take("pepper", "HipRoll", value)
    commands.flush()
    assert counts["refused_values"] == 6 and not commands.targets.get("pepper"), counts
    assert "nan from libmapper is not a finite number — refused, nothing sent to the robot" in said[0], said
    commands.take("pepper", "HipRoll", 3.0)
    commands.flush()
    wait_for(lambda: counts["commands_refused"] == 1, 5, "the owner's refusal")
    assert counts["commands"] == 0
    assert "pepper refused joints/set (HipRoll = 3) from libmapper: out_of_range" in said[-1], said
    assert "nothing moved" in said[-1]
    assert abs(sim.body.pose()["HipRoll"]) < 0.01  # (StandInit: 0, and it stays there)
