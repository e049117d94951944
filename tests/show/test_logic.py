"""The show's pure logic with an injected clock: opening hours, the motors' rest and
cap, the order of idle behaviors, the rehearsal clock. No bus, no robot."""

from __future__ import annotations

import itertools
from datetime import datetime, timedelta
from zoneinfo import ZoneInfo

import pytest

from sonibus.adapters.show.clock import ShowClock, speed_of, start
from sonibus.adapters.show.idle import HOUR_S, Budget, Order
from sonibus.adapters.show.schedule import Schedule, ScheduleError

PARIS = ZoneInfo("Europe/Paris")
MUSEUM = ["tue-sun 10:00-18:00"]


def at(text: str, zone: ZoneInfo = PARIS) -> datetime:
    return datetime.fromisoformat(text).replace(tzinfo=zone)


# -- opening hours ----------------------------------------------------------------------------


def test_open_from_the_first_minute_to_just_before_closing_and_never_on_mondays():
    hours = Schedule.parse(MUSEUM, PARIS)
    assert not hours.is_open(at("2025-06-03 09:59:59"))        # a Tuesday
    assert hours.is_open(at("2025-06-03 10:00:00"))
    assert hours.is_open(at("2025-06-03 17:59:59"))
    assert not hours.is_open(at("2025-06-03 18:00:00"))
    assert not hours.is_open(at("2025-06-02 12:00:00"))        # a Monday
    assert hours.is_open(at("2025-06-08 12:00:00"))            # a Sunday


def test_the_next_change_crosses_the_closed_monday():
    hours = Schedule.parse(MUSEUM, PARIS)
    assert hours.next_change(at("2025-06-08 12:00")) == at("2025-06-08 18:00")   # Sunday: closes
    assert hours.next_change(at("2025-06-08 18:00")) == at("2025-06-10 10:00")   # then Tuesday, not Monday
    assert hours.next_change(at("2025-06-03 10:00")) == at("2025-06-03 18:00")   # (from the very edge: the next)


def test_hours_are_the_zones_local_time_whatever_the_machine_or_the_instants_zone():
    hours = Schedule.parse(MUSEUM, PARIS)
    new_york = ZoneInfo("America/New_York")
    assert hours.is_open(at("2025-06-03 04:00", new_york))     # 10:00 in Paris
    assert not hours.is_open(at("2025-06-03 03:59", new_york))
    tokyo = Schedule.parse(MUSEUM, ZoneInfo("Asia/Tokyo"))
    assert not tokyo.is_open(at("2025-06-03 12:00"))           # noon in Paris is 19:00 in Tokyo


def test_a_summer_time_change_keeps_the_opening_at_ten_local():
    hours = Schedule.parse(["daily 10:00-18:00"], PARIS)
    saturday, sunday = hours.next_change(at("2025-03-29 08:00")), hours.next_change(at("2025-03-30 08:00"))
    assert (saturday.hour, sunday.hour) == (10, 10)            # the clocks went forward on Sunday 02:00
    assert sunday.timestamp() - saturday.timestamp() == timedelta(hours=23).total_seconds()  # a day an hour short
    assert sunday.utcoffset() == timedelta(hours=2) and saturday.utcoffset() == timedelta(hours=1)


def test_touching_rules_make_one_opening_and_closed_dates_close_all_day():
    hours = Schedule.parse([*MUSEUM, "thu 18:00-21:00"], PARIS, closed_on=["2025-12-25"])
    thursday = at("2025-06-05 12:00")
    assert hours.next_change(thursday) == at("2025-06-05 21:00")   # no close at 18:00
    assert not hours.is_open(at("2025-12-25 12:00"))              # a Thursday, but Christmas
    assert hours.next_change(at("2025-12-24 19:00")) == at("2025-12-26 10:00")


def test_ranges_wrap_over_the_weekend_and_no_rules_means_always_open():
    weekend = Schedule.parse(["fri-mon 20:00-24:00"], PARIS)
    assert [weekend.is_open(at(f"2025-06-{d:02d} 21:00")) for d in range(2, 9)] == \
        [True, False, False, False, True, True, True]          # Mon 2 .. Sun 8
    assert weekend.next_change(at("2025-06-06 21:00")) == at("2025-06-07 00:00")
    always = Schedule.parse([], PARIS)
    assert always.is_open(at("2025-06-02 03:00")) and always.next_change(at("2025-06-02 03:00")) is None


@pytest.mark.parametrize("rule, message", [
    ("10:00-18:00", "is not a rule like"),
    ("tue-sun 18:00-10:00", "closes at 10:00, not after it opens at 18:00"),
    ("tuesday 10:00-18:00", "'tuesday' is not a day or range of days"),
    ("tue 10:00-25:00", "25:00 is not a time of day"),
])
def test_a_rule_that_cannot_be_read_says_how_it_should_look(rule, message):
    with pytest.raises(ScheduleError, match=message):
        Schedule.parse([rule], PARIS)


# -- the motors' rest and cap ----------------------------------------------------------------


def test_a_gesture_waits_for_the_rest_after_the_end_of_the_previous_one():
    budget = Budget(rest_s=120, per_hour=100)
    assert budget.next_at(5.0) == 5.0
    budget.started(5.0)
    budget.ended(9.0)
    assert budget.next_at(10.0) == 129.0
    assert budget.next_at(200.0) == 200.0


def test_the_cap_counts_starts_in_a_sliding_hour():
    budget = Budget(rest_s=0, per_hour=3)
    for began in (0.0, 100.0, 200.0):
        budget.started(began)
        budget.ended(began + 5)
    assert budget.next_at(300.0) == HOUR_S              # the first of the three leaves the hour then
    budget.started(HOUR_S)
    assert budget.next_at(HOUR_S + 10) == HOUR_S + 100  # then the second
    assert budget.in_last_hour(HOUR_S + 10) == 3


def test_a_day_of_idle_stays_within_the_cap_where_autoplay_made_thousands():
    """The old museum: a behavior every 20 s, about 4,300 a day. With a rest of 120 s and
    15 an hour, a gesture of 3 s each time the budget allows gives at most 15 an hour."""
    budget, now, starts = Budget(rest_s=120, per_hour=15), 0.0, []
    while now < 8 * HOUR_S:
        now = budget.next_at(now)
        starts.append(now)
        budget.started(now)
        now += 3.0
        budget.ended(now)
    starts.pop()  # (the last one is past the day)
    assert len(starts) <= 8 * 15
    assert all(b - a >= 123.0 for a, b in itertools.pairwise(starts))
    assert all(sum(1 for s in starts if t - HOUR_S < s <= t) <= 15 for t in starts)
    assert 24 * 3600 / 20 > 4300 > len(starts) * 30


# -- the order of idle behaviors -----------------------------------------------------------------


def test_in_order_cycles_and_random_plays_each_once_a_round_never_twice_in_a_row():
    names = ["a", "b", "c", "d"]
    in_order = Order(names, "in order", "x")
    assert [in_order.next() for _ in range(6)] == ["a", "b", "c", "d", "a", "b"]
    order = Order(names, "random", "2025-06-03")
    played = [order.next() for _ in range(40)]
    for round_ in range(10):
        assert sorted(played[4 * round_:4 * round_ + 4]) == names
    assert all(a != b for a, b in itertools.pairwise(played))


def test_the_random_order_is_the_dates_so_a_rehearsal_plays_the_days_order():
    names = [f"b{i}" for i in range(8)]

    def played(seed: str) -> list[str]:
        order = Order(names, "random", seed)
        return [order.next() for _ in range(16)]

    assert played("2025-06-03") == played("2025-06-03")
    assert played("2025-06-03") != played("2025-06-04")


# -- the rehearsal clock ---------------------------------------------------------------------------


class Ticks:
    """A monotonic clock the test moves."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_a_rehearsal_clock_stands_at_its_start_until_it_begins_then_runs_faster():
    ticks = Ticks()
    clock = ShowClock(PARIS, speed=600, start=at("2025-06-03 09:59"), held=True, monotonic=ticks)
    ticks.now += 30
    assert clock.now() == at("2025-06-03 09:59")       # the robot is not there yet: the day waits
    clock.begin()
    ticks.now += 6
    assert clock.now() == at("2025-06-03 10:59")       # 6 real seconds, an hour of the show
    assert clock.real(3600) == 6.0 and clock.rehearsal


def test_a_live_clock_is_the_wall_clock():
    clock = ShowClock(PARIS, wall=lambda: at("2025-06-03 12:00").timestamp(), held=True)
    assert clock.now() == at("2025-06-03 12:00") and not clock.rehearsal and clock.real(60) == 60


def test_rehearsal_options_are_read_or_refused_in_one_line():
    assert speed_of("10m") == 144 and speed_of("1h") == 24 and speed_of("90s") == 960
    assert start("9:55", PARIS, today=at("2025-06-03 00:00").date()) == at("2025-06-03 09:55")
    assert start("2025-06-03 09:55", PARIS) == at("2025-06-03 09:55")
    for bad in ("ten minutes", "10", "0s", "25h"):
        with pytest.raises(ValueError, match=r"duration|between"):
            speed_of(bad)
    with pytest.raises(ValueError, match="not a time like 09:55"):
        start("tomorrow", PARIS)
