"""Options of the ``show`` adapter (docs/show.md has every key with an example).

    [nodes.show]
    adapter = "show"
    robot = "pepper"
    timezone = "Europe/Paris"          # the hours are this zone's local time
    hours = ["tue-sun 10:00-18:00"]

    [nodes.show.idle]
    behaviors = ["animations/Stand/Gestures/Hey_1", "animations/Stand/Gestures/Explain_1"]
    rest_s = 180                       # at least this long between two gestures
    max_per_hour = 12

    [nodes.show.scenarios.hello]
    steps = [{say = "Hello!"}, {behavior = "animations/Stand/Gestures/Hey_1"}]
"""

from __future__ import annotations

import re
import zoneinfo
from dataclasses import dataclass, field
from datetime import tzinfo as TzInfo
from typing import Any, Literal

from sonibus.bus import keys
from sonibus.bus.errors import ConfigError
from sonibus.bus.options import bad, from_mapping

from .schedule import Schedule, ScheduleError

MAX_SAY = 500  # characters of a say step (the say verb's bound)
_NAME = re.compile(r"[A-Za-z0-9_-]{1,64}")  # a scenario's name: what a kiosk, OSC or MIDI asks for


@dataclass(frozen=True)
class Step:
    """One step of a scenario: exactly one of a behavior to run (waiting for its end), a
    text to say (waiting until it is spoken), a posture to reach, or a pause."""

    behavior: str = ""
    say: str = ""
    posture: str = ""
    pause_s: float = 0.0       # show seconds (a rehearsal shortens them)
    speed: float = 0.0         # a posture's speed, a fraction of the joints' maximum (0: the posture verb's default)
    timeout_s: float = 0.0     # real seconds its end may take (0: the show's step_timeout_s)

    def __post_init__(self) -> None:
        given = [k for k in ("behavior", "say", "posture") if getattr(self, k)] + (["pause_s"] if self.pause_s else [])
        if len(given) != 1:
            raise bad("steps", f"a step needs exactly one of behavior, say, posture and pause_s, got "
                               f"{', '.join(given) or 'none'} — e.g. {{say = \"Hello!\"}}")
        if self.pause_s < 0 or self.pause_s > 3600:
            raise bad("pause_s", f"{self.pause_s:g} must be in (0, 3600] seconds")
        if self.say and (not self.say.strip() or len(self.say) > MAX_SAY):
            raise bad("say", f"the text must be 1..{MAX_SAY} characters, not blank")
        if self.speed and (not 0 < self.speed <= 1 or not self.posture):
            raise bad("speed", f"{self.speed:g}: a posture step's speed, in (0, 1]")
        if not 0 <= self.timeout_s <= 3600:
            raise bad("timeout_s", f"{self.timeout_s:g} must be in (0, 3600] seconds (0: the show's step_timeout_s)")

    @property
    def kind(self) -> str:
        return "behavior" if self.behavior else "say" if self.say else "posture" if self.posture else "pause"

    def command(self) -> tuple[str, dict[str, Any]]:
        """The verb and arguments it sends (a pause sends nothing: ``("", {})``)."""
        if self.behavior:
            return "behavior/run", {"name": self.behavior}
        if self.say:
            return "say", {"text": self.say}
        if self.posture:
            return "posture", {"name": self.posture, **({"speed": self.speed} if self.speed else {})}
        return "", {}

    def __str__(self) -> str:
        return f"{self.kind} {self.pause_s:g} s" if self.kind == "pause" else f"{self.kind} {self.command()[1]}"


@dataclass(frozen=True)
class Scenario:
    """A named sequence of steps, run one at a time from a kiosk button, OSC or MIDI."""

    name: str
    steps: tuple[Step, ...]


@dataclass(frozen=True)
class Idle:
    """What the robot plays on its own while the show is open and nobody asks."""

    behaviors: tuple[str, ...] = ()
    order: Literal["random", "in order"] = "random"
    rest_s: float = 120.0        # show seconds between the end of a gesture and the start of the next
    max_per_hour: int = 20       # gestures started in any hour, scenarios' behaviors included
    timeout_s: float = 0.0       # real seconds a gesture may take (0: the show's step_timeout_s)

    def __post_init__(self) -> None:
        if not 0 <= self.rest_s <= 86400:
            raise bad("rest_s", f"{self.rest_s:g} must be in [0, 86400] seconds")
        if not 1 <= self.max_per_hour <= 3600:
            raise bad("max_per_hour", f"{self.max_per_hour} must be in 1..3600")
        if not 0 <= self.timeout_s <= 3600:
            raise bad("timeout_s", f"{self.timeout_s:g} must be in [0, 3600] seconds")
        if any(not b.strip() for b in self.behaviors):
            raise bad("behaviors", "a behavior name is blank")


@dataclass(frozen=True)
class ShowConfig:
    """Options of the ``show`` adapter."""

    robot: str = "pepper"                 # the robot it drives (through its commands only)
    timezone: str = ""                    # the hours' zone: an IANA name ("Europe/Paris"), or "local" (this machine's)
    hours: tuple[str, ...] = ()           # opening hours, e.g. ["tue-sun 10:00-18:00"]; none: always open
    closed_on: tuple[str, ...] = ()       # dates closed all day, e.g. ["2025-12-25"]
    rest_posture: str = "Crouch"          # outside the hours: this posture, then stiffness off
    ready_posture: str = "StandInit"      # at opening (stiffness on first), and when the robot comes back
    idle: dict[str, Any] = field(default_factory=dict)       # [nodes.<name>.idle]: Idle's keys
    scenarios: dict[str, Any] = field(default_factory=dict)  # [nodes.<name>.scenarios.<scenario>]: steps
    step_timeout_s: float = 60.0          # a step (or gesture, or posture) whose end is not heard by then is aborted
    command_timeout_s: float = 5.0        # the robot's owner must answer a command within this
    announce_every_s: float = 60.0        # the show's state is said again this often (a patch started late hears it)
    zone: TzInfo = field(init=False, repr=False, compare=False)
    schedule: Schedule = field(init=False, repr=False, compare=False)
    gestures: Idle = field(init=False, repr=False, compare=False)
    program: dict[str, Scenario] = field(init=False, repr=False, compare=False)  # ``scenarios`` checked

    def __post_init__(self) -> None:
        try:
            keys.check_name("robot", self.robot)
        except ValueError as exc:
            raise bad("robot", str(exc)) from None
        object.__setattr__(self, "zone", _zone(self.timezone, bool(self.hours)))
        try:
            schedule = Schedule.parse(self.hours, self.zone, self.closed_on)
        except ScheduleError as exc:
            raise bad("closed_on" if "date" in str(exc) else "hours", str(exc)) from None
        object.__setattr__(self, "schedule", schedule)
        for key, low, high in (("step_timeout_s", 0.1, 3600), ("command_timeout_s", 0.1, 60),
                               ("announce_every_s", 1, 86400)):
            if not low <= getattr(self, key) <= high:
                raise bad(key, f"{getattr(self, key):g} must be in [{low:g}, {high:g}] seconds")
        for key in ("rest_posture", "ready_posture"):
            if not getattr(self, key):
                raise bad(key, "is empty — name a posture of the robot, e.g. \"Crouch\" (Pepper: Crouch, Stand, "
                               "StandInit, StandZero)")
        object.__setattr__(self, "gestures", _table(Idle, self.idle, "idle"))
        object.__setattr__(self, "program", {name: _scenario(name, table) for name, table in self.scenarios.items()})

    def scenario_timeout(self, step: Step) -> float:
        return step.timeout_s or self.step_timeout_s


def _zone(name: str, needed: bool) -> TzInfo:
    if not name:
        if needed:
            raise bad("timezone", "is missing: the hours are local time of which zone? — e.g. timezone = "
                                  "\"Europe/Paris\" (an IANA name), or \"local\" for this machine's zone")
        return zoneinfo.ZoneInfo("UTC")
    if name == "local":
        from datetime import datetime
        return datetime.now().astimezone().tzinfo  # type: ignore[return-value]
    try:
        return zoneinfo.ZoneInfo(name)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        raise bad("timezone", f"'{name}' is not a time zone — give an IANA name such as \"Europe/Paris\" or "
                              "\"America/New_York\", or \"local\"") from None


def _table(cls: type, table: Any, key: str) -> Any:
    if not isinstance(table, dict):
        raise bad(key, f"must be a table ([nodes.<name>.{key}]), got {table!r}")
    try:
        return from_mapping(cls, table, key)
    except ConfigError as exc:
        raise bad(key, str(exc)) from None


def _scenario(name: str, table: Any) -> Scenario:
    where = f"scenarios.{name}"
    if not _NAME.fullmatch(name):
        raise bad("scenarios", f"{name!r}: a scenario's name must be 1..64 letters, digits, '_' or '-' (what a "
                               "kiosk button, an OSC message or a MIDI note asks for)")
    if not isinstance(table, dict) or set(table) != {"steps"}:
        got = sorted(table) if isinstance(table, dict) else repr(table)
        raise bad("scenarios", f"[{where}] must have only steps = [...] (got {got})")
    steps = table["steps"]
    if not isinstance(steps, list) or not steps or not all(isinstance(s, dict) for s in steps):
        raise bad("scenarios", f"[{where}] steps must be a list of tables such as {{say = \"Hello!\"}}, "
                               "{behavior = \"...\"}, {posture = \"StandInit\"}, {pause_s = 2}")
    try:
        return Scenario(name, tuple(from_mapping(Step, step, f"{where}.steps[{i}]") for i, step in enumerate(steps)))
    except ConfigError as exc:
        raise bad("scenarios", str(exc)) from None
