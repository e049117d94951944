"""What a target receives: the ``sonibus`` address scheme or PepperOSC's.

A profile turns samples, frames and events into encoded OSC datagrams for one
target; it holds no sockets and no timing, so it is easy to test. What OSC
cannot carry raises ``encode.EncodeError``; a frame leaves out just the
messages that cannot be encoded and returns them beside the rest, so one bad
value never costs a target its whole bundle.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

from sonibus.bus.keys import Key

from . import encode
from .config import Target

# The arguments of each event kind, in order; other kinds send their scalar fields sorted by name.
EVENT_ARGS: dict[str, tuple[str, ...]] = {
    "behavior": ("name", "state"), "speech": ("text", "state"), "posture": ("name", "state"),
    "connection": ("state",), "command": ("verb", "ok"),
    "show": ("state",), "scenario": ("name", "state"),  # a show's (adapters/show): open/closed; a scenario's course
}


T = TypeVar("T")
Rendered = tuple[list[bytes], list[encode.EncodeError]]  # datagrams, and what was left out


def each(items: Iterable[T], build: Callable[[T], bytes]) -> Rendered:
    """``build(item)`` of every item; what cannot be encoded is left out, and returned beside."""
    out: list[bytes] = []
    dropped: list[encode.EncodeError] = []
    for item in items:
        try:
            out.append(build(item))
        except encode.EncodeError as exc:
            dropped.append(exc)
    return out, dropped


def event_args(kind: str, fields: dict[str, Any]) -> list[encode.Arg]:
    names = EVENT_ARGS.get(kind) or sorted(k for k in fields if k not in ("t", "kind"))
    out: list[encode.Arg] = []
    for name in names:
        value = fields.get(name)
        if isinstance(value, bool):
            out.append(int(value))  # T/F tags are not understood by every receiver
        elif isinstance(value, int | float | str):
            out.append(value)
    return out


class SonibusProfile:
    """Addresses from the target's templates; one value (or a few) per message."""

    def __init__(self, target: Target) -> None:
        self.target = target
        self._addresses: dict[str, str] = {}

    def address(self, source: Key) -> str:
        found = self._addresses.get(source.key)
        if found is None:
            template = self.target.derived_address if source.section == "derived" else self.target.address
            found = self._addresses[source.key] = template.format(
                robot=source.robot, section=source.section, joint=source.name, name=source.name,
                feature=source.feature, key=source.key)
        return found

    def sample(self, source: Key, values: Sequence[float], t: float, seq: int) -> bytes:
        if not self.target.extra:
            return encode.floats(self.address(source), values)
        extra = [encode.Double(t) if e == "t" else seq & 0x7FFFFFFF for e in self.target.extra]
        return encode.message(self.address(source), *map(float, values), *extra)

    def frame(self, robot: str, t: float, seq: int, samples: list[tuple[Key, Sequence[float]]],
              interval: float) -> Rendered:
        messages, dropped = each(samples, lambda sample: self.sample(sample[0], sample[1], t, seq))
        if not self.target.bundle or not messages:
            return messages, dropped
        return [encode.bundle(encode.timetag(t + self.target.latency_ms / 1000.0), messages)], dropped

    def event(self, robot: str, kind: str, fields: dict[str, Any]) -> bytes | None:
        address = self.target.event_address.format(robot=robot, section="events", kind=kind, name=kind,
                                                   key=f"{robot}/events/{kind}")
        return encode.message(address, *event_args(kind, fields))


class PepperOscProfile:
    """PepperOSC's wire format, byte for byte: its Pd, Max and SuperCollider patches work unchanged.

    Per joint ``/pepperdata "/<Joint>" "/PositionSensor" <float>``, then once per frame
    ``/pepperdata "/latency" <seconds since the previous frame>``; ``/soundstart 1`` when
    a behavior starts and ``/soundstop 1`` when it stops."""

    def __init__(self, target: Target) -> None:
        self.target = target

    def sample(self, source: Key, values: Sequence[float], t: float, seq: int) -> bytes | None:
        return None  # PepperOSC sent whole loops only

    def frame(self, robot: str, t: float, seq: int, samples: list[tuple[Key, Sequence[float]]],
              interval: float) -> Rendered:
        out, dropped = each((s for s in samples if s[0].section == "joints"), lambda sample: encode.message(
            "/pepperdata", f"/{sample[0].name}", "/PositionSensor", float(sample[1][0])))
        if out:
            out.append(encode.message("/pepperdata", "/latency", float(interval)))
        return out, dropped

    def event(self, robot: str, kind: str, fields: dict[str, Any]) -> bytes | None:
        if kind == "behavior" and fields.get("state") == "started":
            return encode.message("/soundstart", 1)
        if kind == "behavior" and fields.get("state") in ("stopped", "failed"):
            return encode.message("/soundstop", 1)
        return None


PROFILES = {"sonibus": SonibusProfile, "pepperosc": PepperOscProfile}
