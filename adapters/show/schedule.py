"""Opening hours: when the show is open, in the installation's own time zone.

Rules are one line each, days then hours, in local time (the zone is said
explicitly, never guessed from the machine)::

    >>> from zoneinfo import ZoneInfo
    >>> from datetime import datetime
    >>> hours = Schedule.parse(["tue-sun 10:00-18:00", "thu 18:00-21:00"], ZoneInfo("Europe/Paris"))
    >>> tuesday = datetime(2025, 6, 3, 9, 30, tzinfo=ZoneInfo("Europe/Paris"))
    >>> hours.is_open(tuesday), hours.next_change(tuesday).strftime("%a %H:%M")
    (False, 'Tue 10:00')
    >>> hours.next_change(datetime(2025, 6, 5, 12, 0, tzinfo=ZoneInfo("Europe/Paris"))).strftime("%a %H:%M")
    'Thu 21:00'

Days: ``mon`` .. ``sun``, ranges (``tue-sun``, ``fri-mon``), lists (``mon,wed``),
``daily``. Hours: ``HH:MM-HH:MM``, the end after the start (``24:00`` ends the
day; a night past midnight is two rules). Rules that touch or overlap join:
``10:00-18:00`` and ``18:00-21:00`` make one opening, with no close between them.
``closed_on`` dates (holidays) are closed all day, whatever the rules say.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import date, datetime, time, timedelta
from datetime import tzinfo as TzInfo

DAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
_RULE = re.compile(r"^\s*(?P<days>[a-z,\-]+)\s+(?P<start>\d{1,2}:\d{2})\s*-\s*(?P<end>\d{1,2}:\d{2})\s*$")
SEARCH_DAYS = 400  # how far ahead a next change is looked for (closed_on dates can close many days in a row)


class ScheduleError(ValueError):
    """A rule, date or zone that cannot be read; the message says which and how it should look."""


@dataclass(frozen=True)
class Rule:
    """Open on ``days`` (0 = Monday) from ``start`` to ``end`` minutes after midnight."""

    days: frozenset[int]
    start: int
    end: int

    @classmethod
    def parse(cls, text: str) -> Rule:
        match = _RULE.match(text.lower())
        if match is None:
            raise ScheduleError(f"{text!r} is not a rule like \"tue-sun 10:00-18:00\" (days, then hours)")
        start, end = _minutes(match["start"], text), _minutes(match["end"], text)
        if not start < end:
            raise ScheduleError(f"{text!r}: it closes at {match['end']}, not after it opens at {match['start']} — "
                                "a night past midnight is two rules (\"fri 20:00-24:00\", \"sat 00:00-02:00\")")
        return cls(_days(match["days"], text), start, end)


@dataclass(frozen=True)
class Schedule:
    """When the show is open; ``rules`` empty: always."""

    rules: tuple[Rule, ...]
    zone: TzInfo
    closed_on: frozenset[date] = frozenset()

    @classmethod
    def parse(cls, rules: Iterable[str], zone: TzInfo, closed_on: Iterable[str] = ()) -> Schedule:
        dates = set()
        for text in closed_on:
            try:
                dates.add(date.fromisoformat(text))
            except ValueError:
                raise ScheduleError(f"{text!r} is not a date like \"2025-12-25\"") from None
        return cls(tuple(Rule.parse(text) for text in rules), zone, frozenset(dates))

    @property
    def always(self) -> bool:
        return not self.rules

    def is_open(self, when: datetime) -> bool:
        """Whether the show is open at ``when`` (any aware time; read in the schedule's zone)."""
        if self.always:
            return True
        instant = when.timestamp()
        day = when.astimezone(self.zone).date()
        return any(start <= instant < end for offset in (-1, 0, 1)
                   for start, end in self._openings(day + timedelta(days=offset)))

    def next_change(self, when: datetime) -> datetime | None:
        """The first instant after ``when`` at which ``is_open`` differs from now (None: never),
        in the schedule's zone (its offset says which of a repeated hour it is); always
        strictly after ``when``."""
        if self.always:
            return None
        now_open, after = self.is_open(when), when.timestamp()
        day = when.astimezone(self.zone).date()
        for offset in range(-1, SEARCH_DAYS):
            for edge in sorted({e for opening in self._openings(day + timedelta(days=offset)) for e in opening}):
                instant = datetime.fromtimestamp(edge, self.zone)
                if edge > after and self.is_open(instant) != now_open:
                    return instant
        return None

    def _openings(self, day: date) -> list[tuple[float, float]]:
        """The day's openings as instants (seconds since the epoch), each from the first
        instant its clock reads the start to the first it reads the end: an hour the clocks
        repeat (autumn) is open or closed once, through both; a start or end the clocks
        skip (spring) is the instant they jump."""
        return [(first_instant(day, start, self.zone), first_instant(day, end, self.zone))
                for start, end in self._spans(day)]

    def _spans(self, day: date) -> list[tuple[int, int]]:
        """The day's openings in minutes after midnight, touching and overlapping rules joined."""
        if day in self.closed_on:
            return []
        spans: list[list[int]] = []
        for start, end in sorted((r.start, r.end) for r in self.rules if day.weekday() in r.days):
            if spans and start <= spans[-1][1]:
                spans[-1][1] = max(spans[-1][1], end)
            else:
                spans.append([start, end])
        return [(start, end) for start, end in spans]

    def describe(self) -> str:
        """The rules as given, for a log line."""
        if self.always:
            return "open all the time (no hours)"
        rules = "; ".join(f"{_days_text(r.days)} {_hhmm(r.start)}-{_hhmm(r.end)}" for r in self.rules)
        closed = f", closed on {', '.join(d.isoformat() for d in sorted(self.closed_on))}" if self.closed_on else ""
        return f"{rules} ({self.zone}){closed}"


def _minutes(text: str, rule: str) -> int:
    hours, minutes = (int(part) for part in text.split(":"))
    if not (0 <= hours <= 24 and 0 <= minutes < 60) or (hours == 24 and minutes):
        raise ScheduleError(f"{rule!r}: {text} is not a time of day (00:00..24:00)")
    return hours * 60 + minutes


def _days(text: str, rule: str) -> frozenset[int]:
    if text == "daily":
        return frozenset(range(7))
    found: set[int] = set()
    for part in text.split(","):
        first, _, last = part.partition("-")
        if first not in DAYS or (last and last not in DAYS):
            raise ScheduleError(f"{rule!r}: {part!r} is not a day or range of days — days: {', '.join(DAYS)} "
                                "or daily, e.g. \"tue-sun\", \"mon,wed\"")
        a, b = DAYS.index(first), DAYS.index(last or first)
        found.update((a + i) % 7 for i in range((b - a) % 7 + 1))  # (fri-mon wraps over the weekend)
    return frozenset(found)


def first_instant(day: date, minute: int, zone: TzInfo) -> float:
    """The first instant (seconds since the epoch) at which the clock of ``zone`` reads
    ``minute`` after midnight of ``day`` or later (24:00: the next midnight): of a time
    that happens twice, the first; of one that never happens, the instant the clocks jump."""
    wall = datetime.combine(day, time()) + timedelta(minutes=minute)
    first = wall.replace(tzinfo=zone, fold=0)  # (PEP 495: fold 0 is the earlier of a repeated time)
    if _reads(first.timestamp(), zone) == wall:
        return first.timestamp()
    # a time the clocks skip: the jump lies between it read at the offset after (before the jump) and before
    before, after = wall.replace(tzinfo=zone, fold=1).timestamp(), first.timestamp()
    before, after = min(before, after), max(before, after)
    while after - before > 1:  # (offsets change on whole seconds)
        middle = (before + after) // 2
        before, after = (before, middle) if _reads(middle, zone) >= wall else (middle, after)
    return after


def _reads(instant: float, zone: TzInfo) -> datetime:
    """What the clock of ``zone`` reads at ``instant`` (naive)."""
    return datetime.fromtimestamp(instant, zone).replace(tzinfo=None)


def _hhmm(minute: int) -> str:
    return f"{minute // 60:02d}:{minute % 60:02d}"


def _days_text(days: frozenset[int]) -> str:
    return ",".join(DAYS[d] for d in sorted(days))
