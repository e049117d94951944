"""What a target receives: the ``sonibus`` address scheme or PepperOSC's.

A profile turns samples, frames and events into encoded OSC datagrams for one
target; it holds no sockets and no timing, so it is easy to test. What OSC
cannot carry raises ``encode.EncodeError``; a frame leaves out just the
messages that cannot be encoded and returns them beside the rest, so one bad
value never costs a target its whole bundle.

For a robot's frames, which bring the same joints again and again, a profile
also works out their datagrams once (``compile``): the same bytes as ``sample``
of each joint or ``frame``, from precomputed addresses and one ``struct.pack``
per message (``tests/osc/test_frame_bytes.py`` compares them for every option).
A derived frame's values, which come the same way, are worked out once too
(``compile_derived``: ``sample`` of each value, for a target of plain messages).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable, Sequence
from operator import itemgetter
from typing import Any, TypeVar

from sonibus.bus.capped import PER_NAME, Capped
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


MAX_ADDRESSES = 10_000        # addresses kept per target, and their bytes
MAX_ADDRESS_BYTES = 4 << 20
SEQ_MASK = 0x7FFFFFFF  # seq as an OSC int32: its low 31 bits


class FrameBytes:
    """One target's datagrams for a robot's frames with one list of joints, worked out
    once: ``render(t, seq, values, interval)`` gives the plain messages (one per joint),
    the bundle, or PepperOSC's loop, byte for byte as the profile does it one joint at
    a time. Raises what ``struct`` raises for a value OSC cannot carry (the caller then
    takes the general path, which leaves out just that message).

    A bundle is packed in one ``struct`` call: its fixed bytes (the head, each element's
    size, address and type tags) and its values are the arguments of one format worked
    out here, the values put in place by slice (no Python code per joint: issue 35)."""

    __slots__ = ("_args", "_extra", "_fill", "_last", "_latency_s", "_pack", "_prefixes", "_shape", "_stride",
                 "_whole")

    def __init__(self, prefixes: tuple[bytes, ...], pack: Callable[..., bytes], extra: tuple[str, ...],
                 shape: str, latency_s: float = 0.0, last: bytes = b"", tags: str = "") -> None:
        self._prefixes = prefixes  # per joint: its address and type tags (with its size first, in a bundle)
        self._pack = pack          # the arguments of one message
        # what follows the value, picked out of (t, seq as int32) in the order of extra ("t", "seq")
        picks = [0 if e == "t" else 1 for e in extra]
        self._extra = (itemgetter(*picks) if len(picks) > 1 else lambda both, i=picks[0]: (both[i],)) \
            if picks else None
        self._shape = shape        # "messages", "bundle" or "pepperosc"
        self._latency_s = latency_s
        self._last = last          # PepperOSC: the prefix of its /latency message
        self._stride = 2 + len(extra)  # a bundle's arguments per joint: its fixed bytes, its value, its extra
        self._fill = tuple((4 + i, e == "t") for i, e in enumerate(extra))  # where each extra goes (True: t)
        self._args: list[Any] = []
        self._whole: Callable[..., bytes] | None = None
        if shape == "bundle":  # ("#bundle\0", its timetag, then per joint its fixed bytes and arguments)
            self._whole = struct.Struct(">8sQ" + "".join(f"{len(p)}s{tags}" for p in prefixes)).pack
            self._args = [b"#bundle\0", 0, *(x for p in prefixes for x in (p, 0.0, *(0 for _ in extra)))]

    def render(self, t: float, seq: int, values: Sequence[float], interval: float = 0.0) -> list[bytes]:
        if self._whole is not None:  # a bundle, in one call (the same bytes as ``encode.bundle`` of the messages)
            args, stride, n = self._args, self._stride, len(self._prefixes)
            seconds = t + self._latency_s + encode.NTP_OFFSET  # (encode.timetag's sum, to the last bit)
            whole = int(seconds)  # (OverflowError, ValueError if not finite: refused, as by timetag)
            args[1] = (whole << 32) | int((seconds - whole) * 2**32)
            args[3::stride] = values  # (ValueError if there are not n of them: an extended slice keeps its size)
            for i, pick in self._fill:
                args[i::stride] = [t if pick else seq & SEQ_MASK] * n
            return [self._whole(*args)]
        pack, pairs = self._pack, zip(self._prefixes, values, strict=True)
        tail = self._extra((t, seq & SEQ_MASK)) if self._extra else ()
        if len(tail) == 2:  # (t and seq: named, as a call with *tail costs a third of the frame)
            a, b = tail
            out = [prefix + pack(v, a, b) for prefix, v in pairs]
        elif tail:
            out = [prefix + pack(v, *tail) for prefix, v in pairs]
        else:
            out = [prefix + pack(v) for prefix, v in pairs]
        if self._shape == "pepperosc":
            out.append(self._last + pack(interval))
        return out


class DerivedBytes:
    """One target's plain messages for derived frames with one list of values and one
    ``shape`` (how many numbers each value holds: 1 for a number), worked out once:
    ``render(t, seq, values)`` gives a message per value, byte for byte what ``sample``
    makes of each (``tests/osc/test_frame_bytes.py``). A value of another shape, or one
    OSC cannot carry, raises what ``struct`` raises (``struct.error``, ``OverflowError``):
    the caller then takes the general path (the count of numbers fixes the type tags, so
    a value that packs is a value of the plan's shape)."""

    __slots__ = ("_extra", "_packs", "_prefixes", "shape")

    def __init__(self, prefixes: tuple[bytes, ...], packs: tuple[Callable[..., bytes], ...],
                 shape: tuple[int, ...], extra: tuple[str, ...]) -> None:
        self._prefixes, self._packs, self.shape = prefixes, packs, shape
        picks = [0 if e == "t" else 1 for e in extra]  # (what follows the numbers: t, seq as int32, as extra says)
        self._extra = itemgetter(*picks) if len(picks) > 1 else (lambda both, i=picks[0]: (both[i],)) \
            if picks else None

    def render(self, t: float, seq: int, values: Sequence[Any]) -> list[bytes]:
        # (a number, or a list of numbers spread as the pack's arguments: the floor's listcomp, issue 35)
        items = zip(self._prefixes, self._packs, values, strict=True)
        if self._extra is None:
            return [prefix + (pack(*v) if v.__class__ is list else pack(v)) for prefix, pack, v in items]
        tail = self._extra((t, seq & SEQ_MASK))
        if len(tail) == 2:  # (t and seq, named: a call with *tail costs more)
            a, b = tail
            return [prefix + (pack(*v, a, b) if v.__class__ is list else pack(v, a, b)) for prefix, pack, v in items]
        return [prefix + (pack(*v, *tail) if v.__class__ is list else pack(v, *tail)) for prefix, pack, v in items]


def shape_of(values: Sequence[Any]) -> tuple[int, ...]:
    """How many numbers each of a derived frame's values holds (1 for a number)."""
    return tuple([len(v) if v.__class__ is list else 1 for v in values])


class SonibusProfile:
    """Addresses from the target's templates; one value (or a few) per message."""

    def __init__(self, target: Target) -> None:
        self.target = target
        # key → its address (keys come from the network: capped; it grew with every key sent before)
        self._addresses: Capped[str, str] = Capped(MAX_ADDRESSES, MAX_ADDRESS_BYTES)

    def address(self, source: Key) -> str:
        found = self._addresses.get(source.key)
        if found is None:
            template = self.target.derived_address if source.section == "derived" else self.target.address
            found = template.format(robot=source.robot, section=source.section, joint=source.name, name=source.name,
                                    feature=source.feature, key=source.key)
            self._addresses.put(source.key, found, len(source.key) + len(found) + 2 * PER_NAME)
        return found

    def compile(self, sources: Sequence[Key]) -> FrameBytes | None:
        """The datagrams of frames of these joints, worked out once (None: an address OSC cannot
        carry; the general path says which)."""
        tags = "f" + "".join("d" if e == "t" else "i" for e in self.target.extra)
        try:
            prefixes = tuple(encode.prefix(self.address(source), tags) for source in sources)
        except ValueError:
            return None
        packer = encode.packer(tags)
        if not self.target.bundle:
            return FrameBytes(prefixes, packer.pack, self.target.extra, "messages")
        sized = tuple(struct.pack(">i", len(prefix) + packer.size) + prefix for prefix in prefixes)
        # (the same sum as ``frame``'s, so the same timetag to the last bit)
        return FrameBytes(sized, packer.pack, self.target.extra, "bundle", self.target.latency_ms / 1000.0,
                          tags=tags)

    def compile_derived(self, sources: Sequence[Key], shape: tuple[int, ...]) -> DerivedBytes | None:
        """The messages of derived frames of these values (``sources``, each holding as many
        numbers as ``shape`` says), worked out once (None: an address OSC cannot carry, a value
        of no number; the general path says which)."""
        extra = "".join("d" if e == "t" else "i" for e in self.target.extra)
        if not all(shape):
            return None
        try:
            prefixes = tuple(encode.prefix(self.address(source), "f" * n + extra)
                             for source, n in zip(sources, shape, strict=True))
        except ValueError:
            return None
        packers = {n: encode.packer("f" * n + extra).pack for n in set(shape)}  # (one per size: 1, 3)
        return DerivedBytes(prefixes, tuple(packers[n] for n in shape), shape, self.target.extra)

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

    def compile(self, sources: Sequence[Key]) -> FrameBytes | None:
        """The loop of frames of these joints, worked out once (None: not joints only)."""
        if any(source.section != "joints" for source in sources):
            return None
        try:
            prefixes = tuple(encode.prefix("/pepperdata", "ssf") + encode.padded(f"/{source.name}")
                             + encode.padded("/PositionSensor") for source in sources)
        except ValueError:
            return None
        last = encode.prefix("/pepperdata", "sf") + encode.padded("/latency")
        return FrameBytes(prefixes, encode.packer("f").pack, (), "pepperosc", last=last)

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
