"""A fuzz of crafted recordings: ``mutants(seed)`` makes files from a valid one
(joint samples, a derived value, events, an info, audio, in two chunks) by one of
``KINDS`` of damage, deterministically from its seed; ``judge`` runs the reading
commands on each in this process and says what went wrong (nothing, if each
succeeded, perhaps with a warning, or was refused in one line that is not an
internal error). The suite runs a small slice (test_strangers.py), ``make bench``
a campaign (bench/recording_fuzz.py).
"""

from __future__ import annotations

import io
import json
import random
import re
import zlib
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import msgpack

from sonibus.bus.cli import Environment, main

from .crafted import T0, Part, Recipe, Topic, craft, jsons, message, samples

TOPICS = [Topic(1, "pepper/joints/HeadYaw", count=30), Topic(2, "pepper/derived/hand/RHand", count=30),
          Topic(3, "pepper/events/behavior", count=4), Topic(4, "pepper/info", count=1),
          Topic(5, "pepper/audio/mic", "msgpack", count=4)]
INTERNAL = re.compile(r"^sonibus: error: \w*(Error|Exception|Exit|Interrupt)\b")  # a Python exception's own name
COMMANDS = ("info", "export", "recover")


def _events(start: int) -> list[bytes]:
    return [json.dumps({"t": (T0 + n * 10**7) / 1e9, "kind": "behavior", "name": "Hey", "state": state}).encode()
            for n, state in zip(range(start, start + 2), ("started", "stopped"), strict=True)]


def info() -> bytes:
    return json.dumps({"robot": "pepper", "model": "pepper", "schema_version": 1, "rate_hz": 50.0,
                       "joints": [{"name": "HeadYaw", "chain": "head", "unit": "rad", "min": -2.0, "max": 2.0,
                                   "max_velocity": 7.0}],
                       "behaviors": [], "postures": [], "adapter": "sim",
                       "owner": {"host": "h", "node": "n"}}).encode()


def _audio(n: int) -> bytes:
    return msgpack.packb({"t": (T0 + n * 10**7) / 1e9, "seq": n, "rate": 16000, "channels": 1, "pcm": b"\0\1" * 160})


def _chunk(start: int, payloads: dict[int, list[bytes]] | None = None) -> bytes:
    """A chunk's records: 15 joint samples and derived values, two events, audio (and the info in the first)."""
    payloads = payloads or {}
    derived = [json.dumps({"t": (T0 + n * 10**7) / 1e9, "seq": n, "v": 0.25}).encode()
               for n in range(start, start + 15)]
    out = samples(1, 15, start) + jsons(2, payloads.get(2, derived), start)
    out += jsons(3, payloads.get(3, _events(start)), start)
    out += b"".join(message(5, start + n, p) for n, p in enumerate(payloads.get(5, [_audio(start), _audio(start + 1)])))
    if start == 0:
        out += jsons(4, payloads.get(4, [info()]), start)
    if 1 in payloads:
        out += jsons(1, payloads[1], start + 100)
    return out


def base() -> Recipe:
    return Recipe(topics=[replace(topic) for topic in TOPICS], parts=[Part(_chunk(0), channels=(1, 2, 3, 4, 5)),
                                              Part(_chunk(15), channels=(1, 2, 3, 5))])


def value(rng: random.Random, depth: int = 0) -> Any:
    """A random JSON value: numbers out of range, wrong types, deep nesting, odd strings."""
    roll = rng.random()
    if depth > 6 or roll < 0.4:
        return rng.choice([0, -1, 1.5, 1e308, -1e308, 2**70, -(2**64), True, None, "", "x" * rng.randint(0, 300),
                           "\u202e\ud7ff\u0000", 1.7e9, rng.random()])
    if roll < 0.7:
        return [value(rng, depth + 1) for _ in range(rng.randint(0, 4))]
    return {rng.choice(["t", "seq", "v", "kind", "name", "state", "joints", "rate_hz", "args", "names", "x"]):
            value(rng, depth + 1) for _ in range(rng.randint(0, 5))}


def payload(rng: random.Random) -> bytes:
    roll = rng.random()
    if roll < 0.15:
        depth = rng.choice([50, 999, 5000, 100_000])
        return rng.choice([b"[" * depth + b"]" * depth, b'{"a":' * depth + b"1" + b"}" * depth, b"[" * depth])
    if roll < 0.25:
        return bytes(rng.randrange(256) for _ in range(rng.randint(0, 40)))
    message_ = value(rng)
    if isinstance(message_, dict) and rng.random() < 0.5:
        message_ = {"t": 1.7e9, "seq": 1, **message_}
    return json.dumps(message_).encode()


def _payloads(rng: random.Random, path: Path) -> bytes:
    channel = rng.choice([1, 2, 3, 4])
    bad = [payload(rng) for _ in range(rng.randint(1, 6))]
    recipe = base()
    recipe.parts[0] = Part(_chunk(0, {channel: bad}), channels=(1, 2, 3, 4, 5))
    return craft(path, recipe)


def _audio_payloads(rng: random.Random, path: Path) -> bytes:
    found = [_packed(value(rng)) if rng.random() < 0.7 else bytes(rng.randrange(256) for _ in range(20))
             for _ in range(3)]
    recipe = base()
    recipe.parts[1] = Part(_chunk(15, {5: found}), channels=(1, 2, 3, 5))
    return craft(path, recipe)


def _packed(item: Any) -> bytes:
    try:
        return msgpack.packb(item)
    except OverflowError:  # (2**70: what msgpack cannot hold)
        return msgpack.packb(str(item))


def _sizes(rng: random.Random, path: Path) -> bytes:
    recipe = base()
    part = recipe.parts[rng.randrange(2)]
    what = rng.choice(["declared", "indexed", "compression", "crc"])
    if what == "declared":
        part.declared = rng.choice([0, 1, len(part.content) - 1, len(part.content) + 1, 2**63, 40 << 20])
    elif what == "indexed":
        part.indexed = rng.choice([0, 1, len(part.content) + 9, 2**64 - 1])
    elif what == "compression":
        part.compression = rng.choice(["lz4", "none", "gzip", "zstd\0", "x" * 200])
        part.data = rng.choice([part.content, None]) if part.compression in ("lz4", "none") else part.content
    else:
        part.crc = False
        part.data = zlib.compress(part.content)
    return craft(path, recipe)


def _garbage_chunk(rng: random.Random, path: Path) -> bytes:
    recipe = base()
    part = recipe.parts[rng.randrange(2)]
    part.compression = rng.choice(["zstd", "lz4"])
    magic = b"\x28\xb5\x2f\xfd" if part.compression == "zstd" else b"\x04\x22\x4d\x18"
    part.data = magic + bytes(rng.randrange(256) for _ in range(rng.randint(0, 400)))
    return craft(path, recipe)


def _flips(rng: random.Random, path: Path) -> bytes:
    data = bytearray(craft(path, base()))
    for _ in range(rng.randint(1, 8)):
        at = rng.randrange(len(data))
        data[at] = rng.randrange(256)
    path.write_bytes(bytes(data))
    return bytes(data)


def _cut(rng: random.Random, path: Path) -> bytes:
    data = craft(path, base())
    data = data[:rng.randrange(1, len(data))] + (data[-8:] if rng.random() < 0.5 else b"")  # (its magic kept, or not)
    path.write_bytes(data)
    return data


def _summary(rng: random.Random, path: Path) -> bytes:
    """Odd topics (Zenoh's wildcards, empty chunks, a section of no one's) and times (backwards, at 2^64)."""
    recipe = base()
    topic = recipe.topics[rng.randrange(len(recipe.topics))]
    topic.topic = rng.choice(["pepper/joints/a*b", "pepper//x", "$x/joints/y", "pepper", "", "pepper/nothing/x",
                              "pepper/joints/" + "é" * 300, "pepper/joints/a b", "/pepper/joints/x", topic.topic])
    recipe.times = rng.choice([(T0, T0 + 10**9), (T0 + 10**9, T0), (0, 2**64 - 1), (2**64 - 1, 0), (T0, T0)])
    topic.count = rng.choice([topic.count, 0, 2**40])
    return craft(path, recipe)


KINDS: dict[str, Callable[[random.Random, Path], bytes]] = {
    "payloads": _payloads, "audio": _audio_payloads, "sizes": _sizes, "garbage chunk": _garbage_chunk,
    "flipped bytes": _flips, "cut": _cut, "summary": _summary}


def mutants(seed: int, count: int, folder: Path) -> Iterator[tuple[str, Path]]:
    """``count`` crafted files in ``folder``, the same for the same ``seed``: (what was done, path)."""
    rng = random.Random(seed)
    names = sorted(KINDS)
    for n in range(count):
        kind = names[n % len(names)]
        path = folder / f"fuzz-{seed}-{n}.mcap"
        KINDS[kind](rng, path)
        yield kind, path


def argv(command: str, path: Path) -> list[str]:
    extra = {"export": ["--csv", str(path) + ".csv", "--wav", str(path) + ".wav"],
             "plot": ["-o", str(path) + ".png"], "recover": ["-o", str(path) + ".recovered.mcap"]}
    return [command, str(path), *extra.get(command, [])]


def judge(path: Path, commands: tuple[str, ...] = COMMANDS) -> list[str]:
    """Run ``commands`` on ``path`` in this process; what went wrong (empty: nothing)."""
    wrong = []
    for command in commands:
        env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
        try:
            status = main(argv(command, path), env)
        except BaseException as exc:  # (what the fuzz looks for)
            wrong.append(f"{command} {path.name}: raised {type(exc).__name__}: {exc}"[:300])
            continue
        lines = env.stderr.getvalue().splitlines()
        if status == 1:
            if len(lines) != 1 or not lines[0].startswith("sonibus: error: ") or INTERNAL.match(lines[0]):
                wrong.append(f"{command} {path.name}: {lines}"[:300])
        elif status != 0 or not all(line.startswith("sonibus: WARNING: ") for line in lines):
            wrong.append(f"{command} {path.name}: status {status}, {lines}"[:300])
    return wrong
