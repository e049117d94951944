"""The OSC command gateway under garbage: it keeps serving, counts what it refuses, loses nothing."""

from __future__ import annotations

import random
import socket
import statistics
import threading
import time

from hypothesis import example, given, settings
from hypothesis import strategies as st

from sonibus import schemas
from sonibus.adapters.osc import shape, wire
from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.bus import CommandError

from ..conftest import free_port, wait_for
from .test_gateway import Client, build, bundle

PACKETS = 10_000
WINDOW = 64  # packets in flight to the gateway: the kernel's UDP buffer must never overflow
WORDS = ["say", "run", "behavior", "list", "x", "joints", "set", "dance", "ç", "a*b", "", "$", "cmd", "ok"]
ARGS = [(), ("hello",), (1,), (0.5, "HeadYaw"), ("HeadYaw", 0.1), (b"\0\1",), (True, None), ("a", "b", "c", 9)]


def pad(text: bytes) -> bytes:
    text += b"\0"
    return text + b"\0" * (-len(text) % 4)


def garbage(rng: random.Random) -> bytes:
    """One packet from one of six families of bad input."""
    kind = rng.randrange(6)
    if kind == 0:  # noise
        return rng.randbytes(rng.randrange(0, 200))
    if kind == 1:  # a valid command cut short
        data = build("/pepper/cmd/joints/set", "HeadYaw", 0.1, "HeadPitch", 0.2)
        return data[:rng.randrange(len(data))]
    if kind == 2:  # type tags that do not match the data, or that python-osc cannot read
        tags = "".join(rng.choice("ifsbhdTFN[]cSIx") for _ in range(rng.randrange(1, 12)))
        return pad(b"/pepper/cmd/say") + pad(b"," + tags.encode()) + rng.randbytes(rng.randrange(0, 40))
    if kind == 3:  # far too many arguments
        return build("/pepper/cmd/joints/set", *([0.25] * rng.randrange(65, 300)))
    if kind == 4:  # random addresses under /pepper/cmd/, random arguments
        verb = "/".join(rng.choice(WORDS) for _ in range(rng.randrange(1, 4)))
        return build(f"/pepper/cmd/{verb}", *rng.choice(ARGS))
    inner = bundle(rng.randbytes(rng.randrange(1, 30)), build("/pepper/cmd/nothing"))
    return bundle(inner, rng.randbytes(rng.randrange(0, 12)), bundle(bundle(inner)))[:rng.randrange(16, 400)]


class Pinger(threading.Thread):
    """Sends a valid command every ~20 ms and expects each reply."""

    def __init__(self, target: tuple) -> None:
        super().__init__(daemon=True)
        self.client = Client(target)
        self.done = threading.Event()
        self.sent = 0
        self.rtts: list[float] = []
        self.failures: list[str] = []

    def run(self) -> None:
        while not self.done.is_set():
            started = time.perf_counter()
            self.sent += 1
            try:
                address, params = self.client.ask("/pepper/cmd/behavior/list")
            except TimeoutError:
                self.failures.append(f"command {self.sent}: no reply")
                continue
            self.rtts.append(time.perf_counter() - started)
            if address != "/pepper/reply/behavior/list" or params[0] != 1:
                self.failures.append(f"command {self.sent}: {address} {params[:3]}")
            self.done.wait(0.02)  # pacing, not synchronisation


def test_garbage_does_not_stop_or_slow_the_gateway(net):
    net.sim("pepper", rate_hz=50)
    gate = net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{free_port(socket.SOCK_DGRAM)}"),
                                name="gate"))
    pinger = Pinger(gate.udp_address)
    pinger.start()
    rng = random.Random(20260301)
    fuzz = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    started = time.perf_counter()
    try:
        for sent in range(1, PACKETS + 1):
            fuzz.sendto(garbage(rng), gate.udp_address)
            if sent - (gate.stats["received"] - pinger.sent) >= WINDOW:
                wait_for(lambda s=sent: s - (gate.stats["received"] - pinger.sent) < WINDOW // 2,
                         what="the gateway reading its backlog")
        wait_for(lambda: gate.stats["received"] - pinger.sent >= PACKETS - 1, what="every packet read")
        elapsed = time.perf_counter() - started
    finally:
        pinger.done.set()
        pinger.join(6)
        fuzz.close()
    stats = gate.stats
    print(f"\n{PACKETS} bad packets in {elapsed:.2f} s ({PACKETS / elapsed:.0f}/s); "
          f"{pinger.sent} commands alongside, round trip median {statistics.median(pinger.rtts) * 1e3:.2f} ms, "
          f"max {max(pinger.rtts) * 1e3:.1f} ms; {stats}")
    assert gate.state == "running"
    assert pinger.failures == [] and pinger.sent >= 20 and len(pinger.rtts) == pinger.sent
    assert stats["internal"] == 0 and stats["busy"] == 0
    assert stats["received"] >= PACKETS + pinger.sent - 1
    for kind in ("malformed", "bad_args", "unknown_address"):
        assert stats[kind] > PACKETS // 50, f"{kind}: {stats[kind]}"
    assert Client(gate.udp_address).ask("/pepper/cmd/behavior/list")[1][0] == 1


OSC_VALUES = st.one_of(st.integers(-2**31, 2**31 - 1), st.floats(width=32), st.text(max_size=12),
                       st.booleans(), st.none(), st.binary(max_size=6))


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=300))
def test_any_bytes_are_messages_or_wire_errors(data):
    try:
        found = wire.messages(data)
    except wire.WireError as exc:
        assert exc.kind == "malformed" and "\n" not in str(exc)
        return
    for item in found:
        try:
            address, args = wire.parse(item)
        except wire.WireError as exc:
            assert exc.kind == "bad_args"
        else:
            assert isinstance(address, str) and isinstance(args, list)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=80), max_size=6))
def test_any_tcp_stream_is_frames_or_a_wire_error(chunks):
    stream = wire.Stream(max_frame=64)
    try:
        for chunk in chunks:
            assert all(isinstance(i, bytes | wire.WireError) for i in stream.feed(chunk))
    except wire.WireError as exc:
        assert exc.kind == "malformed"


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(schemas.command_verbs()), st.lists(OSC_VALUES, max_size=8))
@example("joints/set", ["\n"])  # a joint name with a line break: the error is still one line
def test_arguments_are_shaped_or_refused_as_bad_request(verb, args):
    try:
        request = shape.request(verb, args)
    except CommandError as exc:
        assert exc.code == "bad_request" and "\n" not in exc.message
    else:
        assert isinstance(request, dict)
