"""Instructions per frame (issue 27): the OSC sink's frame path beside ``floor.py``'s
minimal sink, counted by ``valgrind --tool=callgrind``: deterministic, whatever the
load of the machine (user space only: the kernel's part of ``sendto`` is not in them).

One process under callgrind, which dumps its counts (and starts afresh) whenever
``os.getppid`` is entered, called between contenders; only the main thread's counts
are kept (the sink's workers and Zenoh's threads idle meanwhile). Each contender
takes the same msgpack frames (``{t, seq, names, v}`` of ``robot0/frame``), one
call a frame, after a warm-up of as many:

- ``decode``: ``msgpack.unpackb`` alone;
- ``gate``: ``Gate.check`` (decode and check, as every sink does);
- ``floor``: ``floor.py``'s sink callback (unpack, the precomputed datagrams, sent);
- the sink's stages, each on its own (issue 35: where the sonibus frame's instructions go):
  ``select`` a ``Selection`` of its patterns (the gate, then the joints it selects, as an
  ``Incoming``), ``pace`` a ``Spacing``'s turn, ``send`` its target's plan (rendered and
  sent: ``OscSink._frame``), ``latency`` one latency noted for the stats; what ``sonibus``
  spends beyond them is its own dispatch (``Streams.take``, counts, the frame assembler);
- ``sonibus``: an ``osc`` node (``extra = ["t", "seq"]``, ``bundle`` as asked) started
  on a real Zenoh session, given each frame as its frame subscription's callback does
  (``Streams``' ``direct``, its state lock had); its frames' ``t`` are 2 s apart, more than any period the
  pacing learns, so it never holds one back (under valgrind the main thread can wait
  a second for its turn: a stall to the pacing), and ``max_age_ms = 0`` (they are old);
- ``callback``: the same node given each frame as Zenoh's callback gives it (its shared
  subscriber's ``_Shared.dispatch`` on a sample of ``robot1``: a pacing of its own), through
  every layer before the node's take (the fanout, the guard, ``Bus.subscribe``'s callable,
  the node's ``_direct`` and its lock, the state lock released and had again around each);
  ``callback`` − ``sonibus`` is not only those layers: ``_direct`` does the node's own work
  too (what it holds, woken for), which moves from run to run;
- the layers alone (issue 35), on a ``Streams`` of its own session (a ``Fanout`` of its own)
  whose ``direct`` is a plain function that takes the frame: ``stubbed``, its shared
  subscriber's ``dispatch`` on the sample, beside ``plain``, that function given the sample
  as a floor's Zenoh callback would (its key as a string, its payload as bytes); the row
  ``layers`` is ``stubbed`` − ``plain``: what the layers cost a sample.

The derived frame (issue 35: in the show the OSC node takes one beside each robot frame,
26 values each sent as a message, half its work): the same contenders on ``robot0/derived``
frames of ``floor.DERIVED``'s shape (17 scalars, two 3-vectors, 7 scalars), plain messages;
the floor is ``floor_sink(derived=True)``'s callback for them (``Datagrams.derived``), the
sink's ``select`` makes the frame's parts (``Incoming.parts``), its ``send`` is what
``OscSink._take`` does with them once selected (``_derived``: every target's datagrams).

    .venv/bin/python bench/floor_instructions.py [--joints 17 128] [--frames 500] [--derived | --no-derived]

Writes bench/results/floor_instructions.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from common import write
from floor import DERIVED, Datagrams

CONTENDERS = ("decode", "gate", "select", "pace", "send", "latency", "floor", "sonibus", "callback", "plain",
              "stubbed")
SPACING_S = 2.0  # between the frames' t: over pacing.MAX_PERIOD_S, so nothing is paced however slowly valgrind runs


def frames(joints: int, n: int) -> list[bytes]:
    """``n`` frames of ``joints`` values, their ``t`` in the past and ``SPACING_S`` apart."""
    import math

    import msgpack
    names = [f"J{j}" for j in range(joints)]
    t0 = time.time() - n * SPACING_S - 10
    return [msgpack.packb({"t": t0 + i * SPACING_S, "seq": i, "names": names,
                           "v": [math.sin(i + 0.1 * j) for j in range(joints)]}) for i in range(n)]


def derived_frames(n: int) -> list[bytes]:
    """``n`` derived frames of ``floor.DERIVED``'s shape, as ``floor.publish`` puts them, their
    ``t`` as ``frames``'."""
    import math

    import msgpack
    names = [name for name, _ in DERIVED]
    t0 = time.time() - n * SPACING_S - 10
    out = []
    for i in range(n):
        values = [math.sin(i + 0.1 * j) for j in range(len(DERIVED))]
        out.append(msgpack.packb({"t": t0 + i * SPACING_S, "seq": i, "names": names,
                                  "v": [[v, v, v] if size == 3 else v for (_, size), v in zip(DERIVED, values,
                                                                                              strict=True)]}))
    return out


def contenders(joints: int, bundle: bool, port: int, payloads: list[bytes], derived: bool = False) -> tuple[
        dict[str, Callable[[bytes], Any]], Callable[[], Any]]:
    """Each contender as a call on one of ``payloads`` (robot frames, or derived frames), and
    what stops the sonibus one."""
    import msgpack
    import zenoh

    from sonibus.adapters.osc.config import OscSinkConfig
    from sonibus.adapters.osc.sink import OscSink
    from sonibus.bus.keys import Key
    from sonibus.bus.messages import Gate
    from sonibus.bus.node import Bus
    from sonibus.bus.pacing import Spacing
    from sonibus.bus.session import BusConfig, open_session
    from sonibus.bus.stats import Latencies
    from sonibus.bus.streams import Selection
    from sonibus.bus.verdicts import VERDICTS

    key, destination = "robot0/derived" if derived else "robot0/frame", ("127.0.0.1", port)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    datagrams = Datagrams(1, joints)

    def floor(payload: bytes) -> None:
        frame = msgpack.unpackb(payload)
        if derived:  # (floor_sink's each_derived: a datagram a value)
            for datagram in datagrams.derived("robot0", frame["t"], frame["seq"], frame["v"]):
                sock.sendto(datagram, destination)
            return
        if bundle:
            sock.sendto(datagrams.bundle(key, frame["t"], frame["seq"], frame["v"]), destination)
            return
        for datagram in datagrams.messages(key, frame["t"], frame["seq"], frame["v"]):
            sock.sendto(datagram, destination)

    session = open_session(BusConfig(multicast=False, listen=("tcp/127.0.0.1:0",)))
    sink = OscSink(OscSinkConfig(subscribe=("*/derived/**",) if derived else ("*/joints/*",),
                                 targets=(f"127.0.0.1:{port}",), extra=("t", "seq"), bundle=bundle, max_age_ms=0),
                   name="sound")
    bus = Bus(session, node="bench")
    sink.start(bus)
    gate, parsed = Gate(), Key.parse(key)
    # The sink's state lock, held here for the whole run: each frame is taken as ``_direct``
    # takes it once it has the lock. (``_direct`` itself gives a frame to the queue while the
    # forward worker holds the lock, and under valgrind, which runs one thread at a time, the
    # worker, once woken by one such frame, held it for most of the frames after.)
    sink._state.acquire()

    def take(payload: bytes) -> None:
        sink._take(key, payload, time.monotonic())

    class Sample:  # what Zenoh's callback is given: its key expression and its payload, as Zenoh's bytes
        __slots__ = ("attachment", "key_expr", "payload")

        def __init__(self, key_expr: str, payload: bytes) -> None:
            self.key_expr, self.payload, self.attachment = zenoh.KeyExpr(key_expr), zenoh.ZBytes(payload), None

    other = "robot1/derived" if derived else "robot1/frame"
    samples = {payload: Sample(other, payload) for payload in payloads}
    dispatch = bus._subscriptions._shared["*/derived" if derived else "*/frame"].dispatch
    state = sink._state

    def callback(payload: bytes) -> None:
        state.release()  # (``_direct`` takes the lock itself)
        try:
            dispatch(samples[payload])
        finally:
            state.acquire()

    # the layers alone: a Streams of a Bus of its own (its own Fanout) taking each frame in a plain function
    from sonibus.bus.queue import SampleQueue
    from sonibus.bus.streams import Streams
    kept: list[Any] = []

    def stub(key: str, payload: Any) -> bool:
        kept.append(payload)
        kept.clear()
        return True

    stub_bus = Bus(session, node="stub")
    stub_streams = Streams(stub_bus, sink.config.subscribe, SampleQueue(16), direct=stub)
    VERDICTS.leave()  # (its own gate is never asked: nothing remembered for it)
    stub_dispatch = stub_bus._subscriptions._shared["*/derived" if derived else "*/frame"].dispatch

    def plain(payload: bytes) -> None:
        sample = samples[payload]
        stub(str(sample.key_expr), sample.payload.to_bytes())

    def stubbed(payload: bytes) -> None:
        stub_dispatch(samples[payload])

    def close() -> dict[str, int]:
        stub_streams.undeclare()
        sink._state.release()
        counted = dict(sink.stats)
        sink.stop()
        session.close()
        return counted

    # the stages, on objects of their own (the sink's pacing must see each frame once: its own turn)
    selection = Selection(sink.config.subscribe)
    VERDICTS.leave()  # (the sink alone takes frames in its process, as in floor.py: nothing remembered)
    spacing, latencies = Spacing(), Latencies()
    taken = {payload: selection.incoming(key, payload) for payload in payloads}  # (before the counts)
    now = time.monotonic()
    if derived:
        # (what ``_take`` does with a selected derived frame's parts: ``_derived`` where there is one; in a
        # tree from before it, ``_samples`` of them, made one by one by ``select``: the same bench counts both)
        derived_path = getattr(sink, "_derived", None)
        if derived_path is None:
            derived_path = sink._samples
            for message in taken.values():
                tuple(message.parts)  # (made before the counts: ``send`` takes them as the sink would)
            select: Callable[[bytes], Any] = lambda payload: tuple(selection.incoming(key, payload).parts)  # noqa: E731
        else:
            select = lambda payload: selection.incoming(key, payload)  # noqa: E731
        send: Callable[[bytes], Any] = lambda payload: derived_path(taken[payload].parts, now)  # noqa: E731
    else:
        select = lambda payload: selection.incoming(key, payload)  # noqa: E731
        send = lambda payload: sink._frame(taken[payload], now)  # noqa: E731
    return {"decode": msgpack.unpackb, "gate": lambda payload: gate.verdict(parsed, payload),
            "select": select, "pace": lambda payload: spacing.turn(key, taken[payload].t, taken[payload].seq, now),
            "send": send,
            "latency": lambda payload: latencies.add(0.001),
            "floor": floor, "sonibus": take, "callback": callback,
            "plain": plain, "stubbed": stubbed}, close


def segments(joints: int, n: int, bundle: bool, derived: bool = False) -> None:
    """Under callgrind: each contender on ``n`` frames after ``n`` others, ``os.getppid``
    before each and at the end, the collector off (its passes depend on the heap)."""
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))  # (never read: what overflows it is dropped by the kernel)
    payloads = derived_frames(2 * n) if derived else frames(joints, 2 * n)
    calls, close = contenders(joints, bundle, receiver.getsockname()[1], payloads, derived)
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
    if stats.get("received") != 4 * n * (len(DERIVED) if derived else joints) or stats.get("skipped") \
            or stats.get("bad"):
        raise SystemExit(f"the sink did not take every frame as it should: {stats}")


def instructions(joints: int, n: int, bundle: bool, derived: bool = False) -> dict[str, float]:
    """Instructions per frame of each contender, counted in one process under callgrind."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        run = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                              "--dump-before=os_getppid", "--separate-threads=yes", sys.executable, __file__,
                              "--segments", str(joints), str(n), *(["--bundle"] if bundle else []),
                              *(["--derived-frames"] if derived else [])],
                             capture_output=True, text=True, cwd=Path(__file__).parent)
        if run.returncode:
            raise SystemExit(f"callgrind run failed:\n{run.stderr[-3000:]}")
        main = [path for path in Path(tmp).glob("callgrind.out.*-01")]  # (the main thread's dumps)
        main.sort(key=lambda path: int(path.name.rsplit(".", 1)[1].split("-")[0]))
        totals = [int(re.search(r"^(?:summary|totals): (\d+)", path.read_text(), re.M).group(1)) for path in main]
    # dump 1 is the setup and warm-up; then one per contender, each ended by the next getppid
    return {name: total / n for name, total in zip(CONTENDERS, totals[1:], strict=False)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--joints", type=int, nargs="*", default=[17, 128],
                        help="robot frames of so many joints (none: the derived frame alone)")
    parser.add_argument("--frames", type=int, default=500,
                        help="frames counted per contender (deterministic counts: more only takes longer)")
    parser.add_argument("--name", default="floor_instructions", help="results file name")
    parser.add_argument("--segments", type=int, nargs=2, help=argparse.SUPPRESS)  # (the run under callgrind)
    parser.add_argument("--bundle", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--derived-frames", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--derived", action=argparse.BooleanOptionalAction, default=True,
                        help="the derived frame's path too (a row of its own, plain messages)")
    args = parser.parse_args()
    if args.segments:
        segments(*args.segments, args.bundle, args.derived_frames)
        return
    rows = []
    cases = [(joints, bundle, False) for joints in args.joints for bundle in (False, True)]
    for joints, bundle, derived in cases + ([(len(DERIVED), False, True)] if args.derived else []):
        counts = instructions(joints, args.frames, bundle, derived)
        # what the sink spends beyond its stages: Streams.take, its counts, the frame assembler, _take
        counts["dispatch"] = counts["sonibus"] - sum(counts[s] for s in ("select", "pace", "send", "latency"))
        counts["layers"] = counts["stubbed"] - counts["plain"]  # from Zenoh's callback to the node's direct
        rows.append({"joints": joints, "bundle": bundle, "derived": derived, "per_frame": counts,
                     "sonibus_to_floor": counts["sonibus"] / counts["floor"],
                     "gate_to_decode": counts["gate"] / counts["decode"]})
        what = f"{joints:>4} derived values" if derived else f"{joints:>4} joints {'bundle' if bundle else 'plain ':>6}"
        print(f"{what}: " + ", ".join(f"{name} {count / 1000:,.1f}k" for name, count in counts.items())
              + f"; sonibus {rows[-1]['sonibus_to_floor']:.2f}× floor, gate {rows[-1]['gate_to_decode']:.2f}× decode",
              flush=True)
    summary = []
    for r in rows:
        k = {name: f"{count / 1000:,.0f}k" for name, count in r["per_frame"].items()}
        summary.append({"scenario": f"(floor) instructions per derived frame, {r['joints']} values, plain messages"
                        if r["derived"] else f"(floor) instructions per frame, {r['joints']} joints, "
                                             + ("one bundle" if r["bundle"] else "plain messages"),
                        "sonibus": f"{k['sonibus']} (Gate.check {k['gate']})",
                        "baseline": f"floor {k['floor']} (msgpack {k['decode']})",
                        "ratio": f"{r['sonibus_to_floor']:.2f}×", "goal": "", "met": ""})
    write(args.name, {"tree": os.path.dirname(os.path.dirname(__import__("sonibus.bus").bus.__file__)),
                      "frames": args.frames, "rows": rows, "summary": summary})


if __name__ == "__main__":
    main()
