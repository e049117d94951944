"""OSC on the wire, for the command gateway: packets to messages, TCP framing, replies.

>>> from pythonosc.osc_message_builder import OscMessageBuilder
>>> builder = OscMessageBuilder("/pepper/cmd/say")
>>> builder.add_arg("hello")
>>> [parse(m) for m in elements(builder.build().dgram)]
[('/pepper/cmd/say', ['hello'])]
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import Any

from pythonosc import osc_message, slip
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.parsing import osc_types

TAGS = "ifdhsbTFNrmt[]"  # what python-osc parses; others (c, S, I...) would shift every later argument
MAX_ARGS = 64
MAX_DEPTH = 8            # nested bundles
MAX_FRAME = 65536        # bytes of one TCP frame
_PARSE_ERRORS = (osc_types.ParseError, osc_message.ParseError, ValueError, IndexError, struct.error, OverflowError)


class WireError(ValueError):
    """Something that cannot be read; ``kind`` names its counter (``malformed``, ``bad_args``)."""

    def __init__(self, kind: str, message: str, address: str = "") -> None:
        super().__init__(message)
        self.kind = kind
        self.address = address


def elements(packet: bytes, depth: int = 0) -> Iterator[bytes | WireError]:
    """The messages of ``packet`` in order, bundles (nested too) unpacked; a bad
    element yields a ``WireError`` and the elements after it are still read
    when its size is known. Time tags are ignored: everything runs at once."""
    if not OscBundle.dgram_is_bundle(packet):
        yield packet
        return
    if depth >= MAX_DEPTH:
        yield WireError("malformed", f"bundles nested deeper than {MAX_DEPTH}")
        return
    index = 16  # "#bundle\0" and the time tag
    if len(packet) < index:
        yield WireError("malformed", f"bundle of {len(packet)} bytes is shorter than its header")
        return
    while index < len(packet):
        if index + 4 > len(packet):
            yield WireError("malformed", f"bundle element size cut off at byte {index}")
            return
        size = int.from_bytes(packet[index:index + 4], "big", signed=True)
        index += 4
        if not 0 < size <= len(packet) - index:
            yield WireError("malformed", f"bundle element of {size} bytes at byte {index} does not fit")
            return
        yield from elements(packet[index:index + size], depth + 1)
        index += size


def parse(dgram: bytes, max_args: int = MAX_ARGS) -> tuple[str, list[Any]]:
    """``(address, arguments)`` of one OSC message, or ``WireError``."""
    if not OscMessage.dgram_is_message(dgram):
        raise WireError("malformed", "neither an OSC message nor a bundle (no leading '/' or '#bundle')")
    try:
        address, index = osc_types.get_string(dgram, 0)
        tags = osc_types.get_string(dgram, index)[0] if dgram[index:] else ","
    except _PARSE_ERRORS as exc:
        raise WireError("malformed", f"unreadable address or type tags: {exc}") from None
    if not tags.startswith(","):
        raise WireError("malformed", f"type tags {tags[:20]!r} do not start with ','", address)
    unknown = sorted(set(tags[1:]) - set(TAGS))
    if unknown:
        raise WireError("malformed", f"type tag {unknown[0]!r} is not supported (supported: {TAGS})", address)
    count = len(tags) - 1 - tags.count("[") - tags.count("]")
    if count > max_args:
        raise WireError("bad_args", f"{count} arguments, at most {max_args} are accepted", address)
    try:
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
