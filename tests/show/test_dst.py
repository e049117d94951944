"""Issue 33, item 8: the nights the clocks change (Europe/Paris: 2026-03-29 02:00 → 03:00,
2026-10-25 03:00 → 02:00). Opening hours are instants, each from the first instant the
clock reads its start to the first it reads its end; the next change is always strictly
ahead; a rehearsed show across either night keeps its state right and its worker asleep."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any
from zoneinfo import ZoneInfo

import pytest

from sonibus.adapters.show import Show, ShowConfig
from sonibus.adapters.show.clock import start
from sonibus.adapters.show.director import Director
from sonibus.adapters.show.schedule import Schedule

from ..conftest import wait_for
from ..test_commands import connect
from .test_show import ask

PARIS = ZoneInfo("Europe/Paris")
SPRING, AUTUMN = "2026-03-29", "2026-10-25"   # Sundays


def utc(text: str) -> datetime:
    return datetime.fromisoformat(text).replace(tzinfo=UTC)


def iso(when: datetime | None) -> str | None:
    return when.isoformat() if when else None


def test_an_opening_inside_the_spring_gap_opens_when_the_clocks_jump():
    hours = Schedule.parse(["sun 02:30-04:00"], PARIS)
    before = utc(f"{SPRING} 00:59:59")                       # 01:59:59+01:00, the last second before the jump
    assert not hours.is_open(before) and iso(hours.next_change(before)) == f"{SPRING}T03:00:00+02:00"
    assert hours.is_open(utc(f"{SPRING} 01:00")) and iso(hours.next_change(utc(f"{SPRING} 01:00"))) == \
        f"{SPRING}T04:00:00+02:00"
    closes = Schedule.parse(["sun 01:00-02:30"], PARIS)      # a closing the clocks skip: at the jump
    assert closes.is_open(before) and iso(closes.next_change(before)) == f"{SPRING}T03:00:00+02:00"
    skipped = Schedule.parse(["sun 02:10-02:50"], PARIS)     # hours that never happen that night: not open
    assert not any(skipped.is_open(utc(f"{SPRING} 00:00") + timedelta(minutes=m)) for m in range(180))
    assert iso(skipped.next_change(before)) == "2026-04-05T02:10:00+02:00"


def test_hours_across_the_autumn_repeat_stay_open_through_both_hours():
    hours = Schedule.parse(["sun 02:30-04:00"], PARIS)
    first = utc(f"{AUTUMN} 00:59:40")                        # 02:59:40+02:00, 20 s before the clocks go back
    then = utc(f"{AUTUMN} 01:00:00")                         # 02:00:00+01:00: the clock reads 02:00 again
    for when in (first, then, utc(f"{AUTUMN} 01:29:59"), utc(f"{AUTUMN} 02:59:59")):
        assert hours.is_open(when) and iso(hours.next_change(when)) == f"{AUTUMN}T04:00:00+01:00", when
    assert iso(hours.next_change(utc(f"{AUTUMN} 00:00"))) == f"{AUTUMN}T02:30:00+02:00"   # the first 02:30
    once = Schedule.parse(["sun 02:15-02:45"], PARIS)       # inside the repeated hour: the first time only
    assert once.is_open(utc(f"{AUTUMN} 00:20")) and not once.is_open(utc(f"{AUTUMN} 01:20"))
    assert iso(once.next_change(utc(f"{AUTUMN} 00:20"))) == f"{AUTUMN}T02:45:00+02:00"
    assert iso(once.next_change(utc(f"{AUTUMN} 00:45"))) == "2026-11-01T02:15:00+01:00"


@pytest.mark.parametrize("rules", [["sun 02:30-04:00"], ["sun 01:00-02:30"], ["sun 02:10-02:50"],
                                   ["sun 02:15-02:45"], ["daily 00:00-02:00", "daily 03:00-24:00"]])
@pytest.mark.parametrize("night", [SPRING, AUTUMN])
def test_the_next_change_is_always_ahead_and_is_where_the_state_changes(rules, night):
    """Every minute of both nights (UTC 22:00 the day before to 04:00): what a worker waits
    for is strictly later, the state holds until it and changes there."""
    hours = Schedule.parse(rules, PARIS)
    for minute in range(0, 6 * 60, 1):
        when = utc(f"{night} 00:00") - timedelta(hours=2) + timedelta(minutes=minute, seconds=17)
        later = hours.next_change(when)
        assert later is not None and later > when, (when, later)
        assert hours.is_open(later) != hours.is_open(when), (when, later)
        just_before = later.astimezone(UTC) - timedelta(seconds=1)  # (not in PARIS: that is wall time)
        assert hours.is_open(just_before) == hours.is_open(when), (when, later)


def test_from_a_time_that_never_happens_is_refused_and_one_that_happens_twice_is_the_first():
    with pytest.raises(ValueError) as refused:
        start(f"{SPRING} 02:30", PARIS)
    assert str(refused.value) == (f"'{SPRING} 02:30' does not exist in Europe/Paris: that night the clocks go from "
                                  f"02:00 to 03:00 — give a time before or after the jump, e.g. {SPRING} 03:00")
    assert start(f"{AUTUMN} 02:59:40", PARIS).isoformat() == f"{AUTUMN}T02:59:40+02:00"        # the first
    assert start(f"{AUTUMN} 02:59:40+01:00", PARIS).isoformat() == f"{AUTUMN}T02:59:40+01:00"  # the second, asked
    assert start("02:30", PARIS, today=datetime(2026, 10, 25).date()).utcoffset() == timedelta(hours=2)


@pytest.fixture
def ticks(monkeypatch) -> list[float]:
    """When the director's worker went round (its ``_tick``): one per change of the hours, gesture
    or scenario — a worker that spins goes round thousands of times a second."""
    seen: list[float] = []
    tick = Director._tick

    def counted(self: Director) -> None:
        seen.append(self.clock.seconds())
        tick(self)

    monkeypatch.setattr(Director, "_tick", counted)
    return seen


def show_events(rig: Any) -> list[tuple[str, str]]:
    """Each change of the show's state (the state is also said again: once the robot is taken, and every
    ``announce_every_s``), with its clock."""
    changes: list[tuple[str, str]] = []
    for e in rig.events.find("show"):
        if not changes or changes[-1][0] != e["state"]:
            changes.append((e["state"], e["clock"]))
    return changes


def past(rig: Any, until: str) -> dict[str, Any]:
    """The show's status once its clock is past ``until`` (an answer that is an error, a request that
    timed out on a busy machine, is asked again; the last one is said if the clock never gets there)."""
    end = datetime.fromisoformat(until).timestamp()
    last: list[Any] = [None]

    def reached() -> dict[str, Any] | None:
        status = last[0] = ask(rig, "status", {})
        if isinstance(status, dict) and datetime.fromisoformat(status["clock"]).timestamp() >= end:
            return status
        return None
    return wait_for(reached, 20, f"the show's clock past {until}", explain=lambda: f"the last answer: {last[0]}")


def rehearsed(net: Any, begin: str) -> tuple[Any, Show]:
    """A sim robot and its show, open on Sundays 02:30-04:00, rehearsed a minute a second from ``begin``."""
    rig = connect(net)
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["sun 02:30-04:00"],
                           scenarios={"pause": {"steps": [{"pause_s": 1.0}]}}), name="show")
    show.rehearse(60.0, start(begin, show.config.zone))
    net.start(show)
    return rig, show


def test_a_show_across_the_autumn_repeat_stays_open_and_its_worker_asleep(net, ticks):
    """The issue's night: past 02:59:59+02:00 the clock reads 02:00 again. A scenario
    then makes the worker go round: it must find the show still open and sleep until 04:00+01:00."""
    rig, show = rehearsed(net, f"{AUTUMN} 02:57:00")
    past(rig, f"{AUTUMN}T02:00:30+01:00")
    assert ask(rig, "scenario", {"name": "pause"}) == {"name": "pause", "state": "accepted"}
    wait_for(lambda: [e for e in rig.events.find("scenario", name="pause") if e["state"] != "started"], 10,
             "the scenario's end")
    status = past(rig, f"{AUTUMN}T02:02:00+01:00")
    assert len(ticks) <= 10, f"{len(ticks)} turns of the worker in {ticks[-1] - ticks[0]:.0f} s of the show"
    assert [state for state, _ in show_events(rig)] == ["open"]          # never closed in the repeated hour
    assert rig.events.find("scenario", name="pause", state="ended")
    assert status["open"] and status["next"] == f"{AUTUMN}T04:00:00+01:00" and show.state == "running"


def test_a_show_opening_in_the_spring_gap_opens_when_the_clocks_jump(net, ticks):
    rig, show = rehearsed(net, f"{SPRING} 01:57:00")  # (taking the robot takes a second: a minute)
    status = past(rig, f"{SPRING}T03:01:00+02:00")
    events = show_events(rig)
    assert [state for state, _ in events] == ["closed", "open"]
    opened = datetime.fromisoformat(events[1][1]) - datetime.fromisoformat(f"{SPRING}T03:00:00+02:00")
    assert timedelta(0) <= opened <= timedelta(seconds=10), events      # at the jump (a turn of the worker late)
    assert len(ticks) <= 10, f"{len(ticks)} turns of the worker in {ticks[-1] - ticks[0]:.0f} s of the show"
    assert status["open"] and status["next"] == f"{SPRING}T04:00:00+02:00" and show.state == "running"


class Stuck(Schedule):
    """Hours whose next change is now, not ahead — what the autumn night gave before issue 33."""

    def next_change(self, when: datetime) -> datetime | None:
        return when


def test_a_next_change_that_is_not_ahead_fails_the_node_loudly_instead_of_spinning(net, ticks):
    connect(net)  # (the robot the show drives)
    show = Show(ShowConfig(robot="pepper", timezone="Europe/Paris", hours=["daily 00:00-24:00"]), name="show")
    object.__setattr__(show.config, "schedule", Stuck(show.config.schedule.rules, show.config.zone))
    net.start(show)
    wait_for(lambda: show.state == "failed", 10, "the show node failed")
    assert "is not after the show's clock" in show.failure and "a bug" in show.failure
    assert len(ticks) < 100  # (a few turns while it takes the robot, then the failure: a spin makes thousands)
