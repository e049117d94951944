"""The show's clock: the wall clock in the installation's zone, or in a rehearsal
a clock that starts at a chosen instant and runs faster ("a day in ten
minutes"). Everything the show decides by time — opening hours, rests between
gestures, the cap per hour, pauses in scenarios — reads this clock; what the
robot does (a behavior, a sentence, how long a command may take) takes its own,
real time.

>>> from datetime import datetime
>>> from zoneinfo import ZoneInfo
>>> ticks = iter([100.0, 110.0])
>>> clock = ShowClock(ZoneInfo("Europe/Paris"), speed=144,
...                   start=datetime(2025, 6, 3, 9, 55, tzinfo=ZoneInfo("Europe/Paris")),
...                   monotonic=lambda: next(ticks))
>>> clock.now().strftime("%H:%M")        # 10 real seconds later: 24 minutes of the show
'10:19'
>>> clock.real(3600)                      # an hour of the show, in real seconds
25.0
>>> start("2025-06-03 09:55", ZoneInfo("Europe/Paris")).isoformat()
'2025-06-03T09:55:00+02:00'
>>> speed_of("10m")                       # a day in ten minutes
144.0
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from datetime import date, datetime, timedelta
from datetime import time as TimeOfDay
from datetime import tzinfo as TzInfo

from .schedule import first_instant

DAY_S = 86400.0
_DURATION = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*(s|m|min|h)\s*$")  # (a unit always: is "10" s or min?)


class ShowClock:
    """``now()`` in ``zone``; ``seconds()`` since the epoch; ``real(s)`` how long ``s`` of
    the show lasts in real seconds. ``speed`` 1 and no ``start``: the wall clock;
    otherwise a rehearsal, ``held`` at ``start`` until ``begin()`` if asked."""

    def __init__(self, zone: TzInfo, speed: float = 1.0, start: datetime | None = None, held: bool = False,
                 monotonic: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time) -> None:
        if not speed > 0:
            raise ValueError(f"speed {speed:g} must be more than 0")
        self.zone, self.speed = zone, speed
        self._monotonic, self._wall = monotonic, wall
        self.rehearsal = speed != 1.0 or start is not None
        self._origin = start.timestamp() if start is not None else wall()
        # held: a rehearsal's clock stands at its start until begin() (``sonibus rehearse`` begins it once the
        # robot is there: one that takes seconds to connect would miss the start of the rehearsed day)
        self._started: float | None = None if held and self.rehearsal else monotonic()

    def begin(self) -> None:
        """A held clock runs from now on (a running one goes on)."""
        if self._started is None:
            self._started = self._monotonic()

    def seconds(self) -> float:
        """The show's time, in seconds since the epoch."""
        if not self.rehearsal:
            return self._wall()
        if self._started is None:
            return self._origin
        return self._origin + (self._monotonic() - self._started) * self.speed

    def now(self) -> datetime:
        return datetime.fromtimestamp(self.seconds(), self.zone)

    def real(self, show_seconds: float) -> float:
        """Real seconds that ``show_seconds`` of the show take."""
        return show_seconds / self.speed

    def __repr__(self) -> str:
        kind = f"rehearsal ×{self.speed:g}" if self.rehearsal else "live"
        return f"<ShowClock {kind} {self.now().isoformat(timespec='seconds')}>"


def start(text: str, zone: TzInfo, today: date | None = None) -> datetime:
    """When a rehearsal starts, in ``zone``: ``"HH:MM"`` (today), or ``"YYYY-MM-DD HH:MM"``;
    ``ValueError`` saying how it should look."""
    text = text.strip()
    try:
        if re.fullmatch(r"\d{1,2}:\d{2}(:\d{2})?", text):
            padded = text.rjust(len(text) + (text.index(":") == 1), "0")  # (9:55 is 09:55)
            return local(datetime.combine(today or datetime.now(zone).date(), TimeOfDay.fromisoformat(padded)), zone,
                         text)
        found = datetime.fromisoformat(text)
    except ValueError:
        raise ValueError(f"'{text}' is not a time like 09:55 or 2025-06-03 09:55") from None
    return found if found.tzinfo is not None else local(found, zone, text)


def local(wall: datetime, zone: TzInfo, text: str = "") -> datetime:
    """``wall`` (naive, or in ``zone``) as an instant in ``zone``: of a time the clocks go
    through twice (autumn), the first (fold 0: an offset after it, ``+01:00``, says the
    second); ``ValueError`` for a time they skip (spring), naming the jump.

    >>> from zoneinfo import ZoneInfo
    >>> local(datetime(2026, 10, 25, 2, 30), ZoneInfo("Europe/Paris")).isoformat()
    '2026-10-25T02:30:00+02:00'
    """
    naive = wall.replace(tzinfo=None)
    first = naive.replace(tzinfo=zone, fold=0)
    if datetime.fromtimestamp(first.timestamp(), zone).replace(tzinfo=None) == naive:
        return datetime.fromtimestamp(first.timestamp(), zone)
    instant = first_instant(naive.date(), naive.hour * 60 + naive.minute, zone)
    jump = datetime.fromtimestamp(instant, zone)
    skipped = datetime.fromtimestamp(instant - 1, zone) + timedelta(seconds=1)  # (what the clock would have read)
    raise ValueError(f"'{text or naive.isoformat(' ')}' does not exist in {zone}: that night the clocks go from "
                     f"{skipped:%H:%M} to {jump:%H:%M} — give a time before or after the jump, e.g. "
                     f"{jump:%Y-%m-%d %H:%M}")


def speed_of(day: str) -> float:
    """How many times faster the clock runs for a day to last ``day`` (``"10m"``, ``"600s"``,
    ``"1h"``); ``ValueError`` otherwise."""
    match = _DURATION.match(day)
    if match is None:
        raise ValueError(f"'{day}' is not a duration like 10m, 90s or 1h")
    seconds = float(match[1]) * {"s": 1, "m": 60, "min": 60, "h": 3600}[match[2]]
    if not 1 <= seconds <= DAY_S:
        raise ValueError(f"a day of {day} must last between 1 s and 24 h")
    return DAY_S / seconds
