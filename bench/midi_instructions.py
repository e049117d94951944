"""Instructions per frame (issue 35): the MIDI sink's frame path beside ``node_floors.py``'s
``midi_floor``, counted by ``valgrind --tool=callgrind`` (deterministic, whatever the load;
user space only: the kernel's part of JACK's ring buffer is not in them).

One process under callgrind, a private JACK server (dummy driver) beside it, not counted;
the process dumps its counts whenever ``os.getppid`` is entered, called between contenders,
and only the main thread's counts are kept (JACK's process thread, the sink's workers and
Zenoh's threads are not). Each contender takes the same msgpack frames (``{t, seq, names,
v}`` of ``pepper/frame``, 17 joints), one call a frame, after a warm-up of as many:

- ``decode``: ``msgpack.unpackb`` alone;
- ``floor``: ``midi_floor``'s callback (unpack, each joint scaled into 0..127, a control
  change sent through python-rtmidi for each number that changed);
- ``sonibus``: a ``midi`` node (``auto_map``, the robot's info given: its joints' ranges)
  started on a real Zenoh session, given each frame as its frame subscription's callback
  does (``Streams``' ``direct``, its state lock had). The frames' ``t`` are 2 s apart, so
  the pacing never holds one back however slowly valgrind runs.

Two kinds of frames: ``still`` (values that move by less than a MIDI step: nothing sent, as
an idle robot's frames mostly are) and ``moving`` (every joint's number changes: 17 control
changes a frame, each contender).

    .venv/bin/python bench/midi_instructions.py [--frames 500]

Writes bench/results/midi_instructions.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common import write

CONTENDERS = ("decode", "floor", "sonibus")
KINDS = ("still", "moving")
JOINTS = 17
SPACING_S = 2.0  # between the frames' t: over pacing.MAX_PERIOD_S, so nothing is paced however slowly valgrind runs
RANGE = (-8.0, 8.0)  # the joints' range, the floor's (MIDI_RANGE) and the sink's (the robot's info)
KEY = "pepper/frame"


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


def contenders() -> tuple[dict[str, Callable[[bytes], Any]], Callable[[], dict[str, int]]]:
    """Each contender as a call on one payload, and what stops them (the sink's counters back)."""
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


def segments(n: int) -> None:
    """Under callgrind: for each kind of frames, each contender on ``n`` frames after ``n`` others,
    ``os.getppid`` before each and at the end, the collector off (its passes depend on the heap)."""
    calls, close = contenders()
    for kind in KINDS:
        payloads = frames(kind, 2 * n)
        warm, counted = payloads[:n], payloads[n:]
        for call in calls.values():
            for payload in warm:
                call(payload)
        gc.collect()
        gc.disable()
        for call in calls.values():
            os.getppid()
            for payload in counted:
                call(payload)
        os.getppid()
        gc.enable()
    stats = close()
    print(f"sink counters: {stats}", file=sys.stderr)
    if stats.get("received") != len(KINDS) * 2 * n * JOINTS or stats.get("skipped") or stats.get("bad"):
        raise SystemExit(f"the sink did not take every frame as it should: {stats}")


def instructions(n: int) -> dict[str, dict[str, float]]:
    """Instructions per frame of each contender and kind, counted in one process under callgrind."""
    from midi_rate import start_jack, stop_jack
    with tempfile.TemporaryDirectory() as tmp:
        jack = start_jack(Path(tmp) / "jackd.log")
        try:
            out = Path(tmp) / "callgrind.out"
            run = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                                  "--dump-before=os_getppid", "--separate-threads=yes", sys.executable, __file__,
                                  "--segments", str(n)], capture_output=True, text=True, cwd=Path(__file__).parent)
        finally:
            stop_jack(jack)
        if run.returncode:
            raise SystemExit(f"callgrind run failed:\n{run.stderr[-3000:]}")
        main = [path for path in Path(tmp).glob("callgrind.out.*-01")]  # (the main thread's dumps)
        main.sort(key=lambda path: int(path.name.rsplit(".", 1)[1].split("-")[0]))
        totals = [int(re.search(r"^(?:summary|totals): (\d+)", path.read_text(), re.M).group(1)) for path in main]
    # dump 1 is the setup and the first warm-up; then, per kind, one per contender, the last one ended by
    # the next kind's first getppid (its warm-up in the dump after it, dropped)
    per = len(CONTENDERS) + 1
    return {kind: {name: total / n for name, total in zip(CONTENDERS, totals[1 + k * per:], strict=False)}
            for k, kind in enumerate(KINDS)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500,
                        help="frames counted per contender (deterministic counts: more only takes longer)")
    parser.add_argument("--name", default="midi_instructions", help="results file name")
    parser.add_argument("--segments", type=int, help=argparse.SUPPRESS)  # (the run under callgrind)
    args = parser.parse_args()
    if args.segments:
        segments(args.segments)
        return
    rows = []
    for kind, counts in instructions(args.frames).items():
        rows.append({"kind": kind, "per_frame": counts, "sonibus_to_floor": counts["sonibus"] / counts["floor"]})
        print(f"{kind:>6}: " + ", ".join(f"{name} {count / 1000:,.1f}k" for name, count in counts.items())
              + f"; sonibus {rows[-1]['sonibus_to_floor']:.2f}× floor", flush=True)
    summary = [{"scenario": f"(MIDI) instructions per frame, {JOINTS} joints, {r['kind']}",
                "sonibus": f"{r['per_frame']['sonibus'] / 1000:,.0f}k",
                "baseline": f"floor {r['per_frame']['floor'] / 1000:,.0f}k "
                            f"(msgpack {r['per_frame']['decode'] / 1000:,.0f}k)",
                "ratio": f"{r['sonibus_to_floor']:.2f}×", "goal": "", "met": ""} for r in rows]
    write(args.name, {"tree": os.path.dirname(os.path.dirname(__import__("sonibus.bus").bus.__file__)),
                      "frames": args.frames, "rows": rows, "summary": summary})


if __name__ == "__main__":
    main()
