"""Instructions per frame (issue 35): the MIDI sink's and the web node's frame paths beside
``node_floors.py``'s ``midi_floor`` and ``web_floor``, counted by ``valgrind --tool=callgrind``
(deterministic, whatever the load; user space only: the kernel's part is not in them).

One process under callgrind (for MIDI, a private JACK server beside it, not counted); it
dumps its counts whenever ``os.getppid`` is entered, called between contenders, and only
the main thread's counts are kept (JACK's process thread, the nodes' workers and Zenoh's
threads are not). Each contender takes the same msgpack frames (``{t, seq, names, v}`` of
``pepper/frame``, 17 joints), one call a frame, after a warm-up of as many:

- ``decode``: ``msgpack.unpackb`` alone;
- ``floor``: the floor's callback: MIDI, ``midi_floor``'s (unpack, each joint scaled into
  0..127, a control change sent through python-rtmidi for each number that changed); web,
  ``web_floor``'s (unpack, kept as the robot's newest under a lock);
- ``sonibus``: the node (MIDI: ``auto_map``, the robot's info given, its joints' ranges;
  web: the robot shown) started on a real Zenoh session, given each frame as its frame
  subscription's callback does (``Streams``' ``direct``). The frames' ``t`` are 2 s apart,
  so the MIDI sink's pacing never holds one back however slowly valgrind runs.

MIDI takes two kinds of frames: ``still`` (values that move by less than a MIDI step:
nothing sent, as an idle robot's frames mostly are) and ``moving`` (every joint's number
changes: 17 control changes a frame, each contender); web, ``still`` ones (what it does
with a frame does not depend on its values). The web node keeps a frame as it came and
checks the robot's newest when it pushes it (25 a second, on its server's loop, the show's
robots publishing 50): its contender is ``_direct`` each frame and the push's check
(``_checked``) every ``PUSH_EVERY``-th, as the tick takes them; the rest of the push (a
frame made JSON and sent) is not counted: it is the floor's work.

    .venv/bin/python bench/node_instructions.py [--nodes midi web] [--frames 500]

Writes bench/results/node_instructions.json and prints a table.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common import callgrind_totals, counted_calls, write

CONTENDERS = ("decode", "floor", "sonibus")
KINDS = {"midi": ("still", "moving"), "web": ("still",)}
JOINTS = 17
SPACING_S = 2.0  # between the frames' t: over pacing.MAX_PERIOD_S, so nothing is paced however slowly valgrind runs
RANGE = (-8.0, 8.0)  # the joints' range, the floor's (MIDI_RANGE) and the sink's (the robot's info)
KEY = "pepper/frame"
PUSH_EVERY = 2  # frames a web push: the show's robots publish 50 a second, the web node pushes 25


def frames(kind: str, n: int) -> list[bytes]:
    """``n`` frames of ``JOINTS`` values, their ``t`` in the past and ``SPACING_S`` apart: ``still``,
    within a MIDI step of 0 (nothing sent); ``moving``, each joint a step or more from its last."""
    import msgpack
    names = [f"J{j}" for j in range(JOINTS)]
    t0 = time.time() - n * SPACING_S - 10
    step = (RANGE[1] - RANGE[0]) / 127
    if kind == "still":
        values = [[(0.5 + 0.01 * math.sin(i + 0.1 * j)) * step for j in range(JOINTS)] for i in range(n)]
    else:  # (between two numbers four steps apart: every joint sends every frame)
        values = [[(2.5 if i % 2 else -1.5) * step for j in range(JOINTS)] for i in range(n)]
    return [msgpack.packb({"t": t0 + i * SPACING_S, "seq": i, "names": names, "v": v})
            for i, v in enumerate(values)]


def web_contenders() -> tuple[dict[str, Callable[[bytes], Any]], Callable[[], dict[str, int]]]:
    """Each contender of the web node as a call on one payload, and what stops them (the node's
    counters back)."""
    import msgpack

    from sonibus.adapters.web import WebConfig, WebPages
    from sonibus.bus.node import Bus
    from sonibus.bus.session import BusConfig, open_session

    latest: dict[str, dict[str, Any]] = {}
    lock = threading.Lock()

    def floor(payload: bytes) -> None:  # (node_floors.web_floor's keep, its sample's key given)
        frame = msgpack.unpackb(payload)
        with lock:
            latest[KEY.partition("/")[0]] = frame

    session = open_session(BusConfig(multicast=False, listen=("tcp/127.0.0.1:0",)))
    node = WebPages(WebConfig(listen="127.0.0.1:0"), name="web")
    node.start(Bus(session, node="bench"))
    node._robots["pepper"] = {}  # (shown: its frames are kept)

    pushes = [0]

    def take(payload: bytes) -> None:
        if not node._direct(KEY, payload):
            raise SystemExit("the web node gave a frame to its queue")
        pushes[0] += 1
        if pushes[0] % PUSH_EVERY == 0:  # (the tick's part: the newest taken, checked)
            with node._lock:
                latest, node._latest = node._latest, {}
            if len(node._checked(latest)) != 1:
                raise SystemExit("the web node's push did not check the robot's newest frame")

    def close() -> dict[str, int]:
        counted = dict(node.stats)
        node.stop()
        session.close()
        return counted

    return {"decode": msgpack.unpackb, "floor": floor, "sonibus": take}, close


def midi_contenders() -> tuple[dict[str, Callable[[bytes], Any]], Callable[[], dict[str, int]]]:
    """Each contender of the MIDI sink as a call on one payload, and what stops them (the
    sink's counters back)."""
    import msgpack
    import rtmidi

    from sonibus.adapters.midi.config import MidiSinkConfig
    from sonibus.adapters.midi.sink import MidiSink
    from sonibus.bus.node import Bus
    from sonibus.bus.session import BusConfig, open_session

    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "midi-floor")
    out.open_virtual_port("floor")
    low, high = RANGE
    last: dict[tuple[str, int], int] = {}

    def floor(payload: bytes) -> None:  # (node_floors.midi_floor's take, its sample's key given)
        robot, frame = KEY.partition("/")[0], msgpack.unpackb(payload)
        for i, value in enumerate(frame["v"]):
            number = round(min(1.0, max(0.0, (value - low) / (high - low))) * 127)
            if last.get((robot, i)) != number:
                last[robot, i] = number
                out.send_message([0xB0, 20 + i, number])

    session = open_session(BusConfig(multicast=False, listen=("tcp/127.0.0.1:0",)))
    sink = MidiSink(MidiSinkConfig(api="jack", port="bench"), name="midi")
    sink.start(Bus(session, node="bench"))
    sink._state.acquire()  # (held for the whole run: each frame taken as ``_direct`` takes it once it has it)
    sink._robot("pepper")
    sink._learn("pepper", {"joints": [{"name": f"J{j}", "min": RANGE[0], "max": RANGE[1]} for j in range(JOINTS)],
                           "rate_hz": 50.0})

    def take(payload: bytes) -> None:
        sink._take(KEY, payload, time.monotonic())

    def close() -> dict[str, int]:
        sink._state.release()
        counted = dict(sink.stats)
        sink.stop()
        session.close()
        out.close_port()
        out.delete()
        return counted

    return {"decode": msgpack.unpackb, "floor": floor, "sonibus": take}, close


def segments(node: str, n: int) -> None:
    """Under callgrind: for each kind of frames, each contender on ``n`` frames after ``n`` others,
    ``os.getppid`` before each and at the end, the collector off (its passes depend on the heap)."""
    calls, close = (midi_contenders if node == "midi" else web_contenders)()
    for kind in KINDS[node]:
        payloads = frames(kind, 2 * n)
        counted_calls(list(calls.values()), payloads[:n], payloads[n:])
    stats = close()
    print(f"{node} counters: {stats}", file=sys.stderr)
    taken = len(KINDS[node]) * 2 * n * JOINTS  # (the web node counts the nodes' stats it hears too: its own)
    if node == "web":  # (only the frames it pushes: the others were replaced first)
        taken //= PUSH_EVERY
    if not 0 <= stats.get("received", 0) - taken < (100 if node == "web" else 1) or stats.get("skipped") \
            or stats.get("bad"):
        raise SystemExit(f"the {node} node did not take every frame as it should: {stats}")


@contextlib.contextmanager
def jack(node: str, folder: Path) -> Any:
    """A private JACK server for the MIDI contenders while the block runs."""
    if node != "midi":
        yield
        return
    from midi_rate import start_jack, stop_jack
    server = start_jack(folder / "jackd.log")
    try:
        yield
    finally:
        stop_jack(server)


def instructions(node: str, n: int) -> dict[str, dict[str, float]]:
    """Instructions per frame of each contender and kind of ``node``, counted in one process under
    callgrind."""
    with tempfile.TemporaryDirectory() as tmp, jack(node, Path(tmp)):
        totals = callgrind_totals([__file__, "--segments", node, str(n)], Path(__file__).parent)
    # dump 1 is the setup and the first warm-up; then, per kind, one per contender, the last one ended by
    # the next kind's first getppid (its warm-up in the dump after it, dropped)
    per = len(CONTENDERS) + 1
    return {kind: {name: total / n for name, total in zip(CONTENDERS, totals[1 + k * per:], strict=False)}
            for k, kind in enumerate(KINDS[node])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500,
                        help="frames counted per contender (deterministic counts: more only takes longer)")
    parser.add_argument("--nodes", nargs="+", choices=tuple(KINDS), default=list(KINDS))
    parser.add_argument("--name", default="node_instructions", help="results file name")
    parser.add_argument("--segments", nargs=2, help=argparse.SUPPRESS)  # (the run under callgrind: node, frames)
    args = parser.parse_args()
    if args.segments:
        segments(args.segments[0], int(args.segments[1]))
        return
    rows = []
    for node in args.nodes:
        for kind, counts in instructions(node, args.frames).items():
            rows.append({"node": node, "kind": kind, "per_frame": counts,
                         "sonibus_to_floor": counts["sonibus"] / counts["floor"]})
            print(f"{node:>4} {kind:>6}: " + ", ".join(f"{name} {count / 1000:,.1f}k" for name, count in counts.items())
                  + f"; sonibus {rows[-1]['sonibus_to_floor']:.2f}× floor", flush=True)
    summary = [{"scenario": f"({r['node']}) instructions per frame, {JOINTS} joints, {r['kind']}",
                "sonibus": f"{r['per_frame']['sonibus'] / 1000:,.0f}k",
                "baseline": f"floor {r['per_frame']['floor'] / 1000:,.0f}k "
                            f"(msgpack {r['per_frame']['decode'] / 1000:,.0f}k)",
                "ratio": f"{r['sonibus_to_floor']:.2f}×", "goal": "", "met": ""} for r in rows]
    write(args.name, {"tree": os.path.dirname(os.path.dirname(__import__("sonibus.bus").bus.__file__)),
                      "frames": args.frames, "rows": rows, "summary": summary})


if __name__ == "__main__":
    main()
