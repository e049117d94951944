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
        local = when.astimezone(self.zone)
        minute = local.hour * 60 + local.minute + (local.second + local.microsecond / 1e6) / 60
        return any(start <= minute < end for start, end in self._spans(local.date()))

    def next_change(self, when: datetime) -> datetime | None:
        """The first instant after ``when`` at which ``is_open`` differs from now (None: never)."""
        if self.always:
            return None
        now_open = self.is_open(when)
        local = when.astimezone(self.zone)
        for offset in range(SEARCH_DAYS):
            day = local.date() + timedelta(days=offset)
            edges = sorted({edge for span in self._spans(day) for edge in span})
            edges.append(24 * 60)  # (a day's end: an opening may not go on the next day)
            for edge in edges:
                instant = _at(day, edge, self.zone)
                if instant > when and self.is_open(instant) != now_open:
                    return instant
        return None

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


def _at(day: date, minute: int, zone: TzInfo) -> datetime:
    """``minute`` after midnight of ``day`` in ``zone`` (24:00: the next midnight)."""
    return datetime.combine(day, time(), zone) + timedelta(minutes=minute)


def _hhmm(minute: int) -> str:
    return f"{minute // 60:02d}:{minute % 60:02d}"


def _days_text(days: frozenset[int]) -> str:
    return ",".join(DAYS[d] for d in sorted(days))
