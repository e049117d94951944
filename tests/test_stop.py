"""STOP is sacred (issue 26, items 2 and 3), on loopback with real Zenoh sessions: a
claim whose time makes no sense takes nothing from the robot's owner, an owner runs
``stop`` whatever its claim state, a node that goes to stand by first stops its robot
(and its end events are heard), and stopping every robot is one query whatever the
number of robots on the bus. (The web page's STOP: tests/web/test_rogue_bus.py.)"""

from __future__ import annotations

import logging
import threading
import time

import pytest

from sonibus.bus import CommandError, decode, keys, send_command
from sonibus.bus.claimwatch import owners
from sonibus.bus.client import stop_all
from sonibus.bus.ownership import BUS_EPOCH_MS, MAX_ROBOTS, Claim

from .conftest import wait_for

WAVE = "animations/Stand/Gestures/Hey_1"  # about 3 s in the simulator


@pytest.fixture
def pepper(net):
    return net.sim("pepper", rate_hz=50)


def frames_after(bus, robot: str = "pepper"):
    """A function that says whether a frame of ``robot`` arrived since its previous call."""
    _subscriber, queue = bus.subscribe(keys.frame(robot))

    def arrived() -> bool:
        return bool(queue.drain(timeout=0.05))
    return arrived


def test_a_claim_whose_time_makes_no_sense_takes_nothing_from_the_owner(net, pepper, caplog):
    """The issue's spoof: one token ``sonibus/robots/pepper/0/rogue/x`` ("claimed at time 0", so the
    earliest) silenced pepper (50 frames/s → 0) and made it answer stop with ``conflict``."""
    caplog.set_level(logging.WARNING, logger="sonibus")
    watcher = net.bus("watcher")
    arrived = frames_after(watcher)
    wait_for(arrived, what="pepper's frames")
    rogue = net.bus("rogue")
    future = int(time.time() * 1000) + 3_600_000
    spoofs = [f"{keys.ROBOTS}/pepper/0/rogue/x", f"{keys.ROBOTS}/pepper/{future}/rogue/y",
              f"{keys.ROBOTS}/pepper/{BUS_EPOCH_MS - 1}/rogue/z", f"{keys.ROBOTS}/pepper/{'9' * 5000}/rogue/w"]
    tokens = [rogue.token(key) for key in spoofs]  # noqa: F841 (held: a dropped token is undeclared)
    wait_for(lambda: dict(pepper.stats).get("claims_refused", 0) >= len(spoofs), what="the spoofed claims refused",
             explain=lambda: repr(dict(pepper.stats)))
    arrived()
    wait_for(arrived, what="pepper's frames after the spoofs")
    assert pepper.ownership.active and pepper.ownership.owner is None
    refusals = [r.getMessage() for r in caplog.records if "refused the claim" in r.getMessage()]
    assert refusals and "sonibus/robots/pepper/0/rogue/x" in refusals[0] and "before any sonibus bus" in refusals[0]
    assert send_command(watcher, "pepper", "stop", timeout=2.0)["held"] is True
    assert send_command(watcher, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.2]},
                        timeout=2.0)["targets"] == {"HeadYaw": 0.2}
    assert Claim.parse(spoofs[-1]) is None  # 5,000 digits: no claim (int() of it would raise in Zenoh's thread)
    assert pepper.state == "running"


def test_an_owner_standing_by_runs_stop_and_refuses_everything_else(net, pepper):
    watcher = net.bus("watcher")
    mine = pepper.ownership.claim
    rival = Claim("pepper", mine.since_ms - 1000, "elsewhere", "first")
    token = watcher.token(rival.key)  # noqa: F841
    wait_for(lambda: not pepper.ownership.active, what="pepper's owner to stand by")
    # sent to the standby node itself (as a sender that sees it first would): stop runs, a move does not
    assert send_command(watcher, "pepper", "stop", owner=mine, timeout=2.0)["held"] is True
    with pytest.raises(CommandError) as refused:
        send_command(watcher, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [0.2]}, owner=mine,
                     timeout=2.0)
    assert refused.value.code == "conflict"


def test_going_to_stand_by_stops_a_motion_under_way_and_its_end_is_heard(net, pepper):
    """A node that stood by kept its robot moving, and the end of the motion was never said."""
    watcher = net.bus("watcher")
    _subscriber, events = watcher.subscribe(keys.event("pepper", "behavior"))
    send_command(watcher, "pepper", "behavior/run", {"name": WAVE}, timeout=2.0)
    wait_for(lambda: pepper.engine.running_behavior == WAVE, what="the behavior to run")
    rival = Claim("pepper", pepper.ownership.claim.since_ms - 1000, "elsewhere", "first")
    token = watcher.token(rival.key)  # noqa: F841
    wait_for(lambda: not pepper.ownership.active, what="pepper's owner to stand by")
    wait_for(lambda: pepper.engine.running_behavior is None, 2.0, "the behavior stopped by the standby")
    seen: list[dict] = []
    wait_for(lambda: seen.extend(decode(p) for _, p in events.drain(timeout=0.05)) or
             any(e["name"] == WAVE and e["state"] == "stopped" for e in seen), 2.0,
             "the behavior's 'stopped' event", lambda: repr(seen))


def test_stopping_every_robot_is_one_query_whatever_the_robots_on_the_bus(net, pepper):
    """2,000 claims that sort before pepper (and no owner behind them) delayed pepper's stop by
    1.6 s when every robot was sent a stop of its own: here one query reaches every owner."""
    nao = net.sim("nao", rate_hz=50)
    rogue = net.bus("rogue")
    since = int(time.time() * 1000)
    fakes = [f"a{i:04d}" for i in range(2000)]
    tokens = [rogue.token(f"{keys.ROBOTS}/{name}/{since}/rogue/x") for name in fakes]  # noqa: F841
    queries: list[str] = []
    counting = rogue.serve("*/cmd/**", lambda query: queries.append(str(query.key_expr)))  # noqa: F841
    asker = net.bus("asker")
    wait_for(lambda: len(owners(asker).robots()) == MAX_ROBOTS, 20, "the claims at the asker",
             lambda: f"{len(owners(asker).robots())} robots seen")  # (the rest left out: MAX_ROBOTS)
    answered: dict[str, object] = {}
    ended = threading.Event()
    silent: list = []

    def done(robot, outcome) -> None:
        answered[robot] = outcome

    def left(robots, error) -> None:
        silent.append((robots, error))
        ended.set()
    stop_all(asker, done, left, timeout=5.0)
    assert ended.wait(10), "the stop never ended"
    assert {robot: reply["held"] for robot, reply in answered.items()} == {"pepper": True, "nao": True}
    robots, error = silent[0]
    # (the asker keeps MAX_ROBOTS robots, whichever claims came first: pepper and nao among them or not)
    kept = set(owners(asker).robots())
    assert len(kept) == MAX_ROBOTS and set(robots) == kept - {"pepper", "nao"} <= set(fakes)
    assert error.code == "robot_not_found"
    assert queries == ["*/cmd/stop"], f"{len(queries)} queries: {queries[:3]}"
    assert pepper.state == nao.state == "running"
