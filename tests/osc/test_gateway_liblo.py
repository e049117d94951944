"""The gateway's OSC reader against liblo's: valid packets (python-osc's and liblo's own) and
broken ones (cut at every length, bytes after the end, wrong padding, bad blobs, bundles with
bad sizes) go both to ``oscdump`` and to ``wire.messages``; both take and refuse the same ones.

Deliberate differences, kept out of the corpus: an address must start with '/', strings must be
UTF-8, the tags c, S, I (liblo reads them) are refused, arrays (liblo 0.31 refuses them) are read.
"""

from __future__ import annotations

import random
import socket
import struct
import subprocess

import pytest
from pythonosc import osc_bundle_builder
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from sonibus.adapters.osc import wire

from ..conftest import free_port, require_tool, wait_for
from .test_gateway import bundle

WORDS = ["pepper", "cmd", "say", "joints", "set", "x", "stiffness", "a" * 9]
WINDOW = 64  # packets in flight to oscdump


def pad(text: bytes) -> bytes:
    text += b"\0"
    return text + b"\0" * (-len(text) % 4)


def built(rng: random.Random) -> OscMessage:
    """A valid message from python-osc's builder, with arguments of every type liblo and the gateway share."""
    builder = OscMessageBuilder("/" + "/".join(rng.choice(WORDS) for _ in range(rng.randrange(1, 4))))
    for _ in range(rng.randrange(0, 6)):
        kind = rng.choice("ifdhsbTFNm")
        value = {"i": rng.randrange(-2**31, 2**31), "f": rng.uniform(-4, 4), "d": rng.uniform(-1e9, 1e9),
                 "h": rng.randrange(-2**63, 2**63), "s": "".join(rng.choices("abcHY ", k=rng.randrange(0, 9))),
                 "b": rng.randbytes(rng.randrange(1, 7)), "T": True, "F": False, "N": None,
                 "m": (0, 0x90, 60, rng.randrange(128))}[kind]
        builder.add_arg(value, kind)
    return builder.build()


def with_timetag(rng: random.Random) -> bytes:
    """A message with a time tag argument (python-osc's builder has none)."""
    return pad(b"/x/t") + pad(b",tis") + rng.randbytes(8) + struct.pack(">i", 7) + pad(b"ok")


def bundled(rng: random.Random, depth: int = 0) -> OscBundle:
    """A valid bundle from python-osc's builder, nested up to three deep."""
    builder = osc_bundle_builder.OscBundleBuilder(osc_bundle_builder.IMMEDIATELY)
    for _ in range(rng.randrange(0, 4)):
        if depth < 3 and rng.random() < 0.3:
            builder.add_content(bundled(rng, depth + 1))
        else:
            builder.add_content(built(rng))
    return builder.build()


def bad_blobs() -> list[bytes]:
    """Blobs whose size does not fit, or whose padding is missing or not NUL."""
    out = []
    for length in range(6):
        data = bytes(range(1, length + 1))
        padding = -length % 4
        for size in {length - 1, length + 1, length + 4, -1, 2**31 - 1}:
            out.append(pad(b"/b") + pad(b",bi") + struct.pack(">i", size) + data + b"\0" * padding + b"\0\0\0\1")
        out.append(pad(b"/b") + pad(b",b") + struct.pack(">i", length) + data)  # padding missing
        if padding:
            out.append(pad(b"/b") + pad(b",b") + struct.pack(">i", length) + data + b"\1" * padding)
    return out


def resized(elements: list[bytes], index: int, size: int) -> bytes:
    """A bundle of ``elements`` where element ``index`` claims ``size`` bytes."""
    head = b"#bundle\0" + (1).to_bytes(8, "big")
    return head + b"".join(struct.pack(">i", size if i == index else len(e)) + e for i, e in enumerate(elements))


def broken(rng: random.Random, packet: bytes) -> list[bytes]:
    """``packet`` cut at every length, with bytes after its end, with a NUL changed, dropped or added."""
    out = [packet[:n] for n in range(1, len(packet))]
    out += [packet + rng.randbytes(n) for n in (1, 2, 3, 4, 8)] + [packet + b"\0" * 4]
    nuls = [i for i, byte in enumerate(packet) if byte == 0]
    for i in rng.sample(nuls, min(6, len(nuls))):
        out += [packet[:i] + b"\1" + packet[i + 1:], packet[:i] + packet[i + 1:]]
    at = rng.randrange(1, len(packet) + 1)
    out.append(packet[:at] + b"\0" + packet[at:])
    return out


def liblo_made(oscsend: str) -> list[bytes]:
    """Packets liblo's ``oscsend`` builds, caught on a socket."""
    calls = [("/pepper/cmd/joints/set", "sfsff", "HeadYaw", "0.3", "HeadPitch", "-0.1", "0.5"),
             ("/pepper/cmd/say", "sifd", "hello", "3", "0.5", "120"), ("/x", "hsTFN", "-5", "word"),
             ("/pepper/cmd/stop", "")]
    out = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(5)
        for call in calls:
            subprocess.run([oscsend, "127.0.0.1", str(sock.getsockname()[1]), *call], check=True, timeout=10)
            out.append(sock.recv(65536))
    return out


def corpus(rng: random.Random, liblo: list[bytes]) -> list[bytes]:
    valid = [built(rng).dgram for _ in range(16)] + [with_timetag(rng)] + [bundled(rng).dgram for _ in range(8)]
    valid += [*liblo, bundle(), bundle(bundle()), pad(b"/b") + pad(b",b") + bytes(4)]  # an empty blob
    packets = list(valid)
    for packet in valid:
        packets += broken(rng, packet)
    packets += bad_blobs()
    elements = [built(rng).dgram, bundle(built(rng).dgram, bundle(built(rng).dgram)), with_timetag(rng)]
    for index in range(len(elements)):
        for delta in (-4, -1, 1, 4):
            packets.append(resized(elements, index, len(elements[index]) + delta))
        packets += [resized(elements, index, size) for size in (0, -1, 2**31 - 1)]
    packets.append(bundle(bundle(elements[0])[:-1]))  # a nested bundle cut short
    packets.append(b"#bundle\0" + b"\0" * 7)           # a time tag cut short
    return packets


class Oscdump:
    """liblo's ``oscdump`` on a UDP port: which packets it takes whole, and the messages it prints."""

    def __init__(self, spawn) -> None:
        self.port = free_port(socket.SOCK_DGRAM)
        self.process = spawn(require_tool("oscdump", "liblo-tools"), "-L", str(self.port), collect=True, merge=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.marks = 0
        wait_for(lambda: self._mark() and any("/sentinel" in x for x in self.process.lines), what="oscdump up")

    def _mark(self) -> int:
        self.marks += 1
        self.sock.sendto(pad(b"/sentinel") + pad(b",i") + struct.pack(">i", self.marks), ("127.0.0.1", self.port))
        return self.marks

    def read(self, packets: list[bytes]) -> list[tuple[bool, list[tuple[str, str]]]]:
        """For each packet: taken whole (no error), and the (address, type tags) printed for it."""
        out: list[tuple[bool, list[tuple[str, str]]]] = []
        for start in range(0, len(packets), WINDOW):
            del self.process.lines[:]
            marks = []
            for packet in packets[start:start + WINDOW]:
                self.sock.sendto(packet, ("127.0.0.1", self.port))
                marks.append(self._mark())
            last = f"/sentinel i {marks[-1]}"
            wait_for(lambda last=last: any(x.endswith(last) for x in self.process.lines), what="oscdump's output")
            taken, printed = True, []
            for line in list(self.process.lines):
                if "/sentinel i " in line:  # the end of a packet's lines (or a mark left over from the start)
                    if int(line.rsplit(" ", 1)[1]) in marks:
                        out.append((taken, printed))
                    taken, printed = True, []
                elif line.startswith("liblo server error"):
                    taken = False
                else:
                    fields = line.split(" ")
                    printed.append((fields[1], fields[2]))
        return out


@pytest.fixture
def oscdump(spawn):
    dump = Oscdump(spawn)
    yield dump
    dump.sock.close()


def read(packet: bytes) -> tuple[bool, list[tuple[str, str]]]:
    """What the gateway's reader makes of ``packet``: taken, and its (address, type tags)."""
    try:
        found = wire.messages(packet)
    except wire.WireError:
        return False, []
    return True, [(a, t[1:]) for a, t, _ in map(wire.layout, found)]


def test_the_gateway_takes_exactly_the_packets_liblo_takes(oscdump):
    rng = random.Random(13)
    packets = corpus(rng, liblo_made(require_tool("oscsend", "liblo-tools")))
    liblo = oscdump.read(packets)
    assert len(liblo) == len(packets)
    differ = [(p.hex(), liblo_says) for p, liblo_says in zip(packets, liblo, strict=True)
              if liblo_says[0] != read(p)[0] or (liblo_says[0] and liblo_says != read(p))]
    assert differ == [], f"{len(differ)} of {len(packets)} packets read differently, first: {differ[:3]}"
    taken = sum(t for t, _ in liblo)
    print(f"\n{len(packets)} packets: {taken} taken by liblo and the gateway, {len(packets) - taken} refused by both")
    assert taken >= 60 and len(packets) - taken >= 1000, f"{taken} of {len(packets)} taken: the corpus lost its balance"
    for packet in packets:
        if read(packet)[0]:  # what is taken, python-osc reads without a fault
            assert all(isinstance(wire.parse(m, 1024)[1], list) for m in wire.messages(packet))


def test_liblos_own_packets_read_as_sent():
    packets = liblo_made(require_tool("oscsend", "liblo-tools"))
    assert [wire.parse(m) for p in packets for m in wire.messages(p)] == [
        ("/pepper/cmd/joints/set", ["HeadYaw", pytest.approx(0.3), "HeadPitch", pytest.approx(-0.1),
                                    pytest.approx(0.5)]),
        ("/pepper/cmd/say", ["hello", 3, 0.5, 120.0]), ("/x", [-5, "word", True, False, None]),
        ("/pepper/cmd/stop", [])]
