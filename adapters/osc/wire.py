"""OSC on the wire, for the command gateway: packets to messages, TCP framing, replies.

>>> from pythonosc.osc_message_builder import OscMessageBuilder
>>> builder = OscMessageBuilder("/pepper/cmd/say")
>>> builder.add_arg("hello")
>>> [parse(m) for m in messages(builder.build().dgram)]
[('/pepper/cmd/say', ['hello'])]
>>> parse(b"/pepper/cmd/stiffness\\0\\0\\0,sf\\0Body\\0\\0\\0\\0")
Traceback (most recent call last):
sonibus.adapters.osc.wire.WireError: argument 2 (f) needs 4 bytes, 0 left
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any, NamedTuple

from pythonosc import osc_message, slip
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.parsing import osc_types

TAGS = "ifdhsbTFNmt[]"  # liblo's types that python-osc reads, and arrays; c, S, I, r... are refused
MAX_ARGS = 64
MAX_DEPTH = 8            # nested bundles
MAX_FRAME = 65536        # bytes of one TCP frame
BUNDLE = b"#bundle\0"
_SIZES = {"i": 4, "f": 4, "m": 4, "h": 8, "d": 8, "t": 8, "T": 0, "F": 0, "N": 0}
_PARSE_ERRORS = (osc_types.ParseError, osc_message.ParseError, ValueError, IndexError, struct.error, OverflowError)


class WireError(ValueError):
    """Something that cannot be read; ``kind`` names its counter (``malformed``, ``bad_args``),
    ``address`` the message's address and ``addresses`` every address in the packet, when readable."""

    def __init__(self, kind: str, message: str, address: str = "", addresses: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.kind = kind
        self.address = address
        self.addresses = addresses or ((address,) if address else ())


class Layout(NamedTuple):
    """What ``layout`` found in one message."""

    address: str   # "" when it cannot be read
    tags: str      # "" when they cannot be read
    fault: str     # "" when the message is well formed


def layout(dgram: bytes) -> Layout:
    """Check one message by liblo's rules: address and type tags NUL-terminated and
    NUL-padded to 4 bytes, each argument's bytes all there (strings NUL-padded, a
    blob's size within the message and its data padded), nothing after the last
    argument (so the length is a multiple of 4); and the tags in ``TAGS``, brackets
    balanced, strings UTF-8."""
    if dgram[:1] != b"/":
        return Layout("", "", "neither an OSC message (address starting with '/') nor a bundle ('#bundle')")
    address, index, fault = _string(dgram, 0, "the address")
    if fault:
        return Layout("", "", fault)
    if index == len(dgram):
        return Layout(address, "", "no type tag string (',' and one letter per argument) after the address")
    tags, index, fault = _string(dgram, index, "the type tag string")
    if fault:
        return Layout(address, "", fault)
    if not tags.startswith(","):
        return Layout(address, "", f"the type tag string {tags[:20]!r} does not start with ','")
    depth = number = 0
    for tag in tags[1:]:
        if tag in "[]":
            depth += 1 if tag == "[" else -1
            if depth < 0:
                return Layout(address, tags, f"type tags {tags[:40]!r} close an array that is not open")
            continue
        number += 1
        if tag == "s":
            _, index, fault = _string(dgram, index, f"argument {number} (s)")
        elif tag == "b":
            index, fault = _blob(dgram, index, number)
        elif tag in _SIZES:
            if len(dgram) - index < _SIZES[tag]:
                fault = f"argument {number} ({tag}) needs {_SIZES[tag]} bytes, {len(dgram) - index} left"
            index += _SIZES[tag]
        else:
            fault = f"type tag {tag!r} (argument {number}) is not supported (supported: {TAGS})"
        if fault:
            return Layout(address, tags, fault)
    if depth:
        return Layout(address, tags, f"type tags {tags[:40]!r} leave an array open")
    if index != len(dgram):
        return Layout(address, tags, f"{len(dgram) - index} bytes after the last argument")
    return Layout(address, tags, "")


def _string(data: bytes, start: int, what: str) -> tuple[str, int, str]:
    """``(text, index after it, fault)`` of the OSC string at ``start``."""
    nul = data.find(b"\0", start)
    if nul < 0:
        return "", len(data), f"{what} has no terminating NUL"
    end = nul + 4 - (nul - start) % 4
    if end > len(data):
        return "", len(data), f"{what} is cut short: its NUL padding to 4 bytes is missing"
    if data[nul:end].strip(b"\0"):
        return "", end, f"{what} is padded with bytes other than NUL"
    try:
        return data[start:nul].decode("utf-8"), end, ""
    except UnicodeDecodeError:
        return "", end, f"{what} is not UTF-8 text"


def _blob(data: bytes, start: int, number: int) -> tuple[int, str]:
    left = len(data) - start
    if left < 4:
        return start, f"argument {number} (b) needs a 4-byte size, {left} left"
    size = int.from_bytes(data[start:start + 4], "big", signed=True)
    if not 0 <= size <= left - 4:
        return start, f"argument {number} (b) is a blob of {size} bytes, {left - 4} left"
    end = start + 4 + size
    padded = end + -size % 4
    if padded > len(data):
        return start, f"argument {number} (b) is cut short: its NUL padding to 4 bytes is missing"
    if data[end:padded].strip(b"\0"):
        return start, f"argument {number} (b) is padded with bytes other than NUL"
    return padded, ""


def messages(packet: bytes) -> list[bytes]:
    """The messages of ``packet`` in order, bundles (nested too) unpacked, every one well
    formed; else ``WireError`` naming the first fault, with every address that could be
    read: a bundle is taken whole or not at all. Time tags are ignored: all runs at once."""
    found: list[bytes] = []
    addresses: list[str] = []
    faults: list[str] = []
    _walk(packet, 0, "", found, addresses, faults)
    if faults:
        single = addresses[0] if addresses and not packet.startswith(BUNDLE) else ""
        raise WireError("malformed", faults[0], single, tuple(addresses))
    return found


def _walk(data: bytes, depth: int, where: str, found: list[bytes], addresses: list[str], faults: list[str]) -> None:
    """Gather the messages, readable addresses and faults of a packet or bundle element."""
    if not data.startswith(BUNDLE):
        address, _, fault = layout(data)
        if address:
            addresses.append(address)
        if fault:
            faults.append(where + fault)
        else:
            found.append(data)
        return
    if depth >= MAX_DEPTH:
        faults.append(f"{where}bundles nested deeper than {MAX_DEPTH}")
        return
    if len(data) < 16:
        faults.append(f"{where}a bundle of {len(data)} bytes is shorter than its 16-byte header")
        return
    index, number = 16, 0
    while index < len(data):
        number += 1
        left = len(data) - index
        if left < 4:
            faults.append(f"{where}{left} bytes after the last bundle element")
            return
        size = int.from_bytes(data[index:index + 4], "big", signed=True)
        index += 4
        if not 0 < size <= left - 4:
            faults.append(f"{where}bundle element {number} of {size} bytes does not fit in the {left - 4} left")
            return
        inner = f"{where[:-2]}.{number}: " if where else f"element {number}: "
        _walk(data[index:index + size], depth + 1, inner, found, addresses, faults)
        index += size


def parse(dgram: bytes, max_args: int = MAX_ARGS) -> tuple[str, list[Any]]:
    """``(address, arguments)`` of one well-formed OSC message, or ``WireError``."""
    address, tags, fault = layout(dgram)
    if fault:
        raise WireError("malformed", fault, address)
    count = len(tags) - 1 - tags.count("[") - tags.count("]")
    if count > max_args:
        raise WireError("bad_args", f"{count} arguments, at most {max_args} are accepted", address)
    try:  # the layout is checked: python-osc reads exactly what it describes
        return address, OscMessage(dgram).params
    except _PARSE_ERRORS as exc:
        raise WireError("malformed", f"arguments do not match type tags {tags[:20]!r}: {exc}", address) from None


def message(address: str, *args: Any) -> bytes:
    """One OSC message: ints as ``i``, text as ``s``."""
    builder = OscMessageBuilder(address)
    for arg in args:
        builder.add_arg(arg)
    return builder.build().dgram


class Stream:
    """Frames of one TCP connection: SLIP (OSC 1.1, the first byte is END) or an
    int32 size before each packet (OSC 1.0, liblo's default), told apart by the
    first byte. ``feed`` raises ``WireError`` when the stream cannot go on."""

    def __init__(self, max_frame: int = MAX_FRAME) -> None:
        self.slip: bool | None = None
        self.max_frame = max_frame
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[bytes | WireError]:
        """The packets completed by ``data`` (bad SLIP frames as ``WireError``)."""
        self._buffer += data
        if self.slip is None and self._buffer:
            self.slip = self._buffer[0] == slip.END[0]
        return list(self._slip() if self.slip else self._sized())

    def frame(self, packet: bytes) -> bytes:
        """``packet`` framed as this connection frames its packets."""
        return slip.encode(packet) if self.slip is not False else struct.pack(">i", len(packet)) + packet

    def _slip(self) -> Iterator[bytes | WireError]:
        *frames, rest = bytes(self._buffer).split(slip.END)
        self._buffer = bytearray(rest)
        for frame in frames:
            if frame:
                try:
                    yield slip.decode(frame)
                except slip.ProtocolError:
                    yield WireError("malformed", "SLIP frame with a bad escape sequence")
        if len(self._buffer) > self.max_frame:
            raise WireError("malformed", f"SLIP frame longer than {self.max_frame} bytes")

    def _sized(self) -> Iterator[bytes | WireError]:
        while len(self._buffer) >= 4:
            size = int.from_bytes(self._buffer[:4], "big", signed=True)
            if not 0 < size <= self.max_frame:
                raise WireError("malformed", f"TCP frame size {size} is not in 1..{self.max_frame}")
            if len(self._buffer) < 4 + size:
                return
            packet = bytes(self._buffer[4:4 + size])
            del self._buffer[:4 + size]
            yield packet
