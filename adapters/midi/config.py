"""Options of the MIDI sink (``midi``) and controller (``midi-in``).

    [nodes.daw]
    adapter = "midi"
    port = "sonibus"                                      # a virtual output port
    map = [{key = "pepper/joints/HeadYaw", cc = 1, resolution = 14}]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, TypeVar

from sonibus.bus import keys
from sonibus.bus.errors import ConfigError
from sonibus.bus.options import bad, from_mapping
from sonibus.bus.plan import without_audio
from sonibus.bus.robot import load_model

from .mapping import BEHAVIOR_NOTES, SPEECH_NOTE

Api = Literal["auto", "jack", "alsa", "coreaudio", "windows"]
T = TypeVar("T")


def _range(key: str, value: int, low: int, high: int) -> None:
    if not low <= value <= high:
        raise bad(key, f"{value} must be in {low}..{high}")


def _tables(cls: type[T], key: str, entries: tuple[dict[str, Any], ...]) -> tuple[T, ...]:
    out = []
    for index, entry in enumerate(entries):
        try:
            out.append(from_mapping(cls, entry, f"{key}[{index}]"))
        except ConfigError as exc:
            raise bad(key, str(exc)) from None
    return tuple(out)


def _robot(robot: str) -> None:
    try:
        keys.check_name("robot", robot)
    except ValueError as exc:
        raise bad("robot", str(exc)) from None


def _port(port: str, connect: str) -> None:
    if not port and not connect:
        raise bad("port", "is empty — name the virtual port to open, or give connect = \"part of a port name\"")


@dataclass(frozen=True, kw_only=True)
class MapEntry:
    """One controller of the sink: ``{key = "pepper/joints/HeadYaw", cc = 1, resolution = 14}``
    or ``{key = ..., pitchbend = true}``; a derived key (``pepper/derived/qom/RArm``) sends its first number."""

    key: str
    cc: int = -1
    channel: int = 0          # 0: the robot's channel
    resolution: Literal[7, 14] = 7
    pitchbend: bool = False

    def __post_init__(self) -> None:
        robot, section, name = ([*self.key.split("/", 2), "", ""])[:3]
        if not robot or section not in ("joints", "derived") or not name or "*" in self.key \
                or ("/" in name) != (section == "derived"):
            raise bad("key", f"'{self.key}' is not a joint key such as \"pepper/joints/HeadYaw\" "
                             f"or a derived key such as \"pepper/derived/qom/RArm\"")
        _range("channel", self.channel, 0, 16)
        if self.pitchbend:
            if self.cc != -1:
                raise bad("cc", f"{self.cc}: give either cc or pitchbend = true, not both")
        elif self.resolution == 14:
            _range("cc", self.cc, 0, 31)  # the LSB goes on cc + 32
        else:
            _range("cc", self.cc, 0, 119)


@dataclass(frozen=True, kw_only=True)
class MidiSinkConfig:
    """Options of the ``midi`` adapter."""

    port: str = "sonibus"               # the virtual output port opened
    connect: str = ""                   # instead: an existing port, by name or part of it
    api: Api = "auto"
    subscribe: str | tuple[str, ...] = ("*/joints/*", "*/events/*")
    channels: dict[str, int] | None = None   # robot → channel 1..16 (others: in the order first seen)
    map: tuple[dict[str, Any], ...] = ()     # explicit controllers (MapEntry)
    auto_map: bool = True               # other joints: CC 20 + index in the robot's joint table
    max_rate_hz: float = 0.0            # at most this many messages per controller per second (0: all)
    notes: bool = True                  # behavior and speech events as notes
    behavior_note: int = -1             # one fixed note for every behavior; -1: a note per behavior (below)
    behavior_notes: dict[str, int] | None = None            # behavior name → its note
    behavior_note_range: tuple[int, int] = BEHAVIOR_NOTES   # other behaviors: hashed onto these notes
    speech_note: int = SPEECH_NOTE
    velocity: int = 100
    queue: int = 8192
    per_joint_keys: bool = False        # joints from <robot>/joints/* instead of <robot>/frame (bus/streams.py)

    def __post_init__(self) -> None:
        _port(self.port, self.connect)
        object.__setattr__(self, "subscribe", without_audio(keys.patterns(self.subscribe), "a MIDI sink"))
        for robot, channel in (self.channels or {}).items():
            if not isinstance(channel, int) or isinstance(channel, bool) or not 1 <= channel <= 16:
                raise bad("channels", f"{robot} = {channel!r} must be a channel in 1..16")
        entries = _tables(MapEntry, "map", self.map)
        seen: dict[tuple[int, int | str, str], str] = {}
        for entry in entries:
            slot = (entry.channel, "pb" if entry.pitchbend else entry.cc, entry.key.split("/")[0])
            if slot in seen or entry.key in seen.values():
                raise bad("map", f"'{entry.key}' uses the same key or controller as '{seen.get(slot, entry.key)}'")
            seen[slot] = entry.key
        object.__setattr__(self, "_entries", {e.key: e for e in entries})
        if self.max_rate_hz < 0:
            raise bad("max_rate_hz", f"{self.max_rate_hz:g} must be 0 (no cap) or more")
        if self.behavior_note != -1:
            _range("behavior_note", self.behavior_note, 0, 127)
        for behavior, number in (self.behavior_notes or {}).items():
            if not isinstance(number, int) or isinstance(number, bool) or not 0 <= number <= 127:
                raise bad("behavior_notes", f"'{behavior}' = {number!r} must be a note in 0..127")
        low, high = self.behavior_note_range
        if not 0 <= low <= high <= 127:
            raise bad("behavior_note_range", f"[{low}, {high}] must be two notes in 0..127, the lowest first")
        _range("speech_note", self.speech_note, 0, 127)
        _range("velocity", self.velocity, 1, 127)
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")

    @property
    def entries(self) -> dict[str, MapEntry]:
        return self._entries  # type: ignore[attr-defined, no-any-return]


def check_joint(key: str, robot: str, joint: str) -> None:
    """``ConfigError`` naming ``key`` when ``robot`` is of a known model (its name without
    digits: ``pepper2`` → pepper) and that model has no ``joint``; others are checked when
    ``<robot>/info`` arrives."""
    try:
        model = load_model(robot.rstrip("0123456789"))
    except KeyError:
        return
    if not model.has_joint(joint):
        raise bad(key, f"{robot} has no joint '{joint}' — known joints: {', '.join(model.joint_names)}")


@dataclass(frozen=True, kw_only=True)
class CcMapping:
    """``{cc = 1, channel = 1, robot = "pepper", joint = "HeadYaw", speed = 0.3}``"""

    cc: int
    robot: str
    joint: str
    channel: int = 1
    speed: float = 0.3

    def __post_init__(self) -> None:
        _range("cc", self.cc, 0, 119)
        _range("channel", self.channel, 1, 16)
        _robot(self.robot)
        if not 0 < self.speed <= 1:
            raise bad("speed", f"{self.speed:g} must be in (0, 1]")
        check_joint("joint", self.robot, self.joint)


@dataclass(frozen=True, kw_only=True)
class NoteMapping:
    """``{note = 60, channel = 1, robot = "pepper", behavior = "animations/Stand/Gestures/Hey_1"}``,
    or ``scenario = "hello"``: a scenario of the robot's show (docs/show.md)."""

    note: int
    robot: str
    behavior: str = ""
    scenario: str = ""
    channel: int = 1
    stop_on_release: bool = False     # note off → behavior/stop

    def __post_init__(self) -> None:
        _range("note", self.note, 0, 127)
        _range("channel", self.channel, 1, 16)
        _robot(self.robot)
        if bool(self.behavior) == bool(self.scenario):
            raise bad("behavior", "give exactly one of behavior (a behavior to run: sonibus send ROBOT "
                                  "behavior/list) and scenario (a scenario of the robot's show)")
        if self.scenario and self.stop_on_release:
            raise bad("stop_on_release", "is for behaviors: a scenario runs to its end (a stop mapping stops it)")


@dataclass(frozen=True, kw_only=True)
class ProgramMapping:
    """``{channel = 1, robot = "pepper", postures = ["StandInit", "Crouch"]}``: program N → posture N."""

    robot: str
    postures: tuple[str, ...]
    channel: int = 1
    speed: float = 0.3

    def __post_init__(self) -> None:
        _range("channel", self.channel, 1, 16)
        _robot(self.robot)
        if not self.postures or len(self.postures) > 128:
            raise bad("postures", "give 1..128 posture names (program 0 is the first)")
        if not 0 < self.speed <= 1:
            raise bad("speed", f"{self.speed:g} must be in (0, 1]")


@dataclass(frozen=True, kw_only=True)
class StopMapping:
    """``{robot = "pepper", note = 0}`` or ``{robot = "pepper", cc = 119}``: the panic button."""

    robot: str
    note: int = -1
    cc: int = -1
    channel: int = 1

    def __post_init__(self) -> None:
        _robot(self.robot)
        _range("channel", self.channel, 1, 16)
        if (self.note == -1) == (self.cc == -1):
            raise bad("note", "give exactly one of note or cc")
        _range("note" if self.note != -1 else "cc", max(self.note, self.cc), 0, 127)


@dataclass(frozen=True, kw_only=True)
class MidiControllerConfig:
    """Options of the ``midi-in`` adapter."""

    port: str = "sonibus-in"            # the virtual input port opened
    connect: str = ""                   # instead: an existing port, by name or part of it
    api: Api = "auto"
    cc: tuple[dict[str, Any], ...] = ()       # CcMapping: fader → joints/set
    notes: tuple[dict[str, Any], ...] = ()    # NoteMapping: key → behavior/run, or a show's scenario
    program: tuple[dict[str, Any], ...] = ()  # ProgramMapping: program change → posture
    stop: tuple[dict[str, Any], ...] = ()     # StopMapping: note or CC → stop
    rate_hz: float = 20.0               # joints/set per robot per second at most (the newest values)
    timeout: float = 5.0                # seconds a robot has to answer
    queue: int = 4096                   # MIDI messages waiting before the oldest are dropped (a flood)

    def __post_init__(self) -> None:
        _port(self.port, self.connect)
        if self.queue < 1:
            raise bad("queue", f"{self.queue} must be at least 1")
        if not self.rate_hz > 0:
            raise bad("rate_hz", f"{self.rate_hz:g} must be more than 0")
        if not self.timeout > 0:
            raise bad("timeout", f"{self.timeout:g} s must be more than 0")
        parsed = {"cc": _tables(CcMapping, "cc", self.cc), "notes": _tables(NoteMapping, "notes", self.notes),
                  "program": _tables(ProgramMapping, "program", self.program),
                  "stop": _tables(StopMapping, "stop", self.stop)}
        object.__setattr__(self, "_parsed", parsed)

    def mappings(self, kind: str) -> tuple[Any, ...]:
        return self._parsed[kind]  # type: ignore[attr-defined, no-any-return]
