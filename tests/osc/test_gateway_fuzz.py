"""The OSC command gateway under garbage: it keeps serving, counts what it refuses, loses nothing,
and runs nothing from a malformed packet."""

from __future__ import annotations

import itertools
import random
import socket
import statistics
import threading
import time
from collections.abc import Callable
from typing import Any

from hypothesis import example, given, settings
from hypothesis import strategies as st
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from sonibus import schemas
from sonibus.adapters.osc import wire
from sonibus.adapters.osc.gateway import OscGateway, OscGatewayConfig
from sonibus.bus import CommandError
from sonibus.bus.commands import from_osc

from ..conftest import free_port, wait_for
from .test_gateway import Client, Watch, build, bundle

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
        request = from_osc(verb, args)
    except CommandError as exc:
        assert exc.code == "bad_request" and "\n" not in exc.message
    else:
        assert isinstance(request, dict)


# -- malformed commands never run: cut and over-long arguments, bundles valid, broken and nested --

FAMILIES = ("message", "cut", "long", "bundle", "bundle_cut", "bundle_long", "bundle_size")
PER_FAMILY = 50
ADDRESS_END = 16  # "/pepper/cmd/say" and its NUL: a cut before this leaves no address to answer
Tree = bytes | list  # a message, or a bundle of trees


def say(data: st.DataObject, token: str) -> bytes:
    """``/pepper/cmd/say token [volume [speed]]``, numbers as ``f`` or ``d``, ``i`` or ``h``."""
    builder = OscMessageBuilder("/pepper/cmd/say")
    builder.add_arg(token, "s")
    for values, kinds in ((st.floats(0, 1, width=32), "fd"), (st.integers(50, 400), "ih")):
        if not data.draw(st.booleans()):
            break
        builder.add_arg(data.draw(values), data.draw(st.sampled_from(kinds)))
    return builder.build().dgram


def render(tree: Tree, leaf: int = -1, change: Callable[[bytes], bytes] | None = None,
           element: int = -1, size: Callable[[int], int] | None = None) -> bytes:
    """``tree`` as bytes; the ``leaf``-th message passed through ``change``, or the
    ``element``-th bundle element (in document order) claiming ``size(its length)`` bytes."""
    counter = {"leaf": -1, "element": -1}

    def walk(node: Tree) -> bytes:
        if isinstance(node, bytes):
            counter["leaf"] += 1
            return change(node) if change and counter["leaf"] == leaf else node
        out = b"#bundle\0" + (1).to_bytes(8, "big")
        for child in node:
            counter["element"] += 1
            index = counter["element"]
            body = walk(child)
            claimed = size(len(body)) if size and index == element else len(body)
            out += claimed.to_bytes(4, "big", signed=True) + body
        return out

    return walk(tree)


def shape_of(data: st.DataObject, tokens: list[str], depth: int = 0) -> list:
    """A bundle of 1-3 elements, messages or bundles nested up to two deep."""
    tree: list = []
    for _ in range(data.draw(st.integers(1, 3))):
        if depth < 2 and data.draw(st.booleans()):
            tree.append(shape_of(data, tokens, depth + 1))
        else:
            tokens.append(f"fz{next(TOKENS):07d}")
            tree.append(say(data, tokens[-1]))
    return tree


TOKENS = itertools.count()
SIZES = [*(lambda n, d=d: n + d for d in (-8, -4, -3, -1, 1, 2, 4, 8)), lambda n: 0, lambda n: -1, lambda n: 2**31 - 1]


def elements(tree: Tree) -> int:
    """Bundle elements in ``tree``, nested ones included."""
    return 0 if isinstance(tree, bytes) else sum(1 + elements(child) for child in tree)


def cut_or_pad(data: st.DataObject, family: str, message: bytes) -> tuple[bytes, bool]:
    """``message`` cut short or with bytes after it, and whether its address can still be read."""
    if family.endswith("cut"):
        at = data.draw(st.integers(1, len(message) - 1))
        return message[:at], at >= ADDRESS_END
    return message + data.draw(st.binary(min_size=1, max_size=12)), True


def test_malformed_commands_never_run_and_valid_ones_are_answered(net):
    net.sim("pepper", rate_hz=50)
    gate = net.start(OscGateway(OscGatewayConfig(listen=f"127.0.0.1:{free_port(socket.SOCK_DGRAM)}"),
                                name="gate"))
    client = Client(gate.udp_address)
    commands = Watch(net, "pepper/events/command")
    tried = dict.fromkeys(FAMILIES, 0)
    refused = dict.fromkeys(FAMILIES, 0)
    carried = dict.fromkeys(FAMILIES, 0)  # commands in the packets sent
    family_of: dict[str, str] = {}
    valid: set[str] = set()
    assert client.ask("/pepper/cmd/say", "fz-start")[1][0] == 1  # the watch on command events is up
    wait_for(lambda: commands.all(), what="the first command event")

    def replies_until_ping() -> list[tuple[str, list[Any]]]:
        client.send(build("/pepper/cmd/behavior/list"))
        got = []
        while (reply := client.reply())[0] != "/pepper/reply/behavior/list":
            got.append(reply)
        return got

    def one(family: str, data: st.DataObject) -> None:
        tokens: list[str] = []
        tree: Tree = shape_of(data, tokens) if family.startswith("bundle") else say(data, f"fz{next(TOKENS):07d}")
        if isinstance(tree, bytes):
            tokens.append(OscMessage(tree).params[0])
        family_of.update(dict.fromkeys(tokens, family))
        malformed = gate.stats["malformed"]
        if family in ("message", "bundle"):
            client.send(render(tree))
            answers = [client.reply() for _ in tokens]
            assert all(a == "/pepper/reply/say" and p[0] == 1 for a, p in answers), answers
            valid.update(tokens)
            tried[family] += 1
            carried[family] += len(tokens)
            return
        if family == "bundle_size":  # small changes only: cutting off exactly a whole last element is valid
            packet = render(tree, element=data.draw(st.integers(0, elements(tree) - 1)),
                            size=data.draw(st.sampled_from(SIZES)))
            client.send(packet)
            answers = replies_until_ping()
        else:
            leaf = data.draw(st.integers(0, len(tokens) - 1))
            readable = True

            def broken(message: bytes) -> bytes:
                nonlocal readable
                message, readable = cut_or_pad(data, family, message)
                return message

            client.send(broken(tree) if isinstance(tree, bytes) else render(tree, leaf, broken))
            answers = replies_until_ping()
            assert len(answers) == len(tokens) - (not readable), answers
        assert all(a == "/pepper/reply/say" and p[:2] == [0, "bad_request"] for a, p in answers), answers
        assert len(answers) <= len(tokens)
        wait_for(lambda: gate.stats["malformed"] == malformed + 1, what="the malformed packet counted")
        tried[family] += 1  # counted once sent: Hypothesis may drop an example while drawing it
        refused[family] += 1
        carried[family] += len(tokens)

    for family in FAMILIES:
        settings(max_examples=PER_FAMILY, deadline=None, database=None)(
            given(st.just(family), st.data())(one))()
    wait_for(lambda: valid <= {e["args"].get("text") for e in commands.all()}, what="every valid command run")
    assert client.ask("/pepper/cmd/say", "fz-end")[1][0] == 1
    wait_for(lambda: any(e["args"].get("text") == "fz-end" for e in commands.all()), what="the last command run")
    executed = [e["args"]["text"] for e in commands.all() if e["verb"] == "say" and e["ok"]]
    ran = {f: sum(family_of.get(t) == f for t in executed) for f in FAMILIES}
    print("\nfamily: packets sent/refused, commands in them/run — " + ", ".join(
        f"{f}: {tried[f]}/{refused[f]}, {carried[f]}/{ran[f]}" for f in FAMILIES))
    assert set(executed) == valid | {"fz-start", "fz-end"} and len(executed) == len(valid) + 2
    assert ran == {f: carried[f] if f in ("message", "bundle") else 0 for f in FAMILIES}
    assert all(tried[f] >= PER_FAMILY // 2 for f in FAMILIES), tried
    assert gate.stats["malformed"] == sum(refused.values())
    assert gate.stats["internal"] == 0 and client.nothing_waiting()
