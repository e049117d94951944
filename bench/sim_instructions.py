"""Instructions per frame (issue 35): the sim's frame (``SimRobot.ticker``: the engine
moved on, the frame checked and published) beside its floor (``floor.publish``'s frame: 17
values made, packed, put), counted by ``valgrind --tool=callgrind``: deterministic,
whatever the load of the machine (user space only, the main thread only: Zenoh's ``tx``
thread, which writes the batches to the sockets, is not in them).

One process under callgrind, which dumps its counts (and starts afresh) whenever
``os.getppid`` is entered, called between contenders. Its session connects to an anchor
beside ``show.FRAME_TAKERS`` sessions (another process, not under callgrind) that take
every ``*/frame``, as the show's nodes take the sim's: each put goes to every taker.
Each contender is called ``--frames`` times after a warm-up of as many:

- ``floor``: ``floor.publish``'s frame (its own publisher, its QoS);
- the sim's stages, each on its own: ``advance`` (``SimEngine.advance``: idle motion and a
  step of the body), ``publish`` (``RobotAdapter.publish_frame``: the frame made, checked,
  counted and put), of which ``encode`` (``codec.FrameEncoder``, names packed once) and
  ``put`` (the frame publisher's ``put`` of an encoded frame);
- ``sim``: the whole tick (``SimRobot.ticker``), Pepper with idle motion, as in the show.

    .venv/bin/python bench/sim_instructions.py [--frames 500]

Writes bench/results/sim_instructions.json and prints a table.
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

from common import free_port, write, zenoh_config
from floor import CONTEXT
from show import FRAME_TAKERS, takers_of

CONTENDERS = ("floor", "advance", "encode", "put", "publish", "sim")
JOINTS = 17  # a Pepper's


def contenders(endpoint: str) -> tuple[dict[str, Callable[[int], Any]], Callable[[], dict[str, int]]]:
    """Each contender as a call on a frame number, and what stops the robot (its counters)."""
    import msgpack
    import zenoh

    from sonibus.adapters.sim.adapter import SimConfig, SimRobot
    from sonibus.bus import codec, framing
    from sonibus.bus.node import Bus
    from sonibus.bus.session import BusConfig, open_session

    class Driven(SimRobot):
        """The sim with no frame loop of its own: the bench calls its tick."""

        def _acquire(self) -> None:
            self.stopping.wait()

    session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    robot = Driven(SimConfig(robot="pepper", model="pepper", rate_hz=50, idle=True, body_sound=False,
                             speaker=False), name="sim")
    robot.start(Bus(session, node="bench"))
    # the floor's publisher, as floor.publish declares it
    floor_publisher = session.declare_publisher("floor0/frame", priority=zenoh.Priority.DATA_HIGH,
                                                congestion_control=zenoh.CongestionControl.DROP, express=False)
    publishers = robot.ownership._publishers
    deadline = time.monotonic() + 60
    while not (floor_publisher.matching_status.matching and publishers._frame.matching_status.matching):
        if time.monotonic() > deadline:
            raise SystemExit("no taker matched the publishers")
        time.sleep(0.05)
    time.sleep(3)  # (the gossip links every taker's session to this one)
    names = [f"J{j}" for j in range(JOINTS)]

    def floor(seq: int) -> None:
        t = time.time()
        values = [math.sin(t + 0.1 * j) for j in range(JOINTS)]
        floor_publisher.put(msgpack.packb({"t": t, "seq": seq, "names": names, "v": values}))

    engine, body_names, tick = robot.engine, robot.engine.body.names, robot.ticker()
    positions = list(robot.body.positions)
    message = framing.frame(time.time(), 0, body_names, positions)
    payload = codec.encode(message)

    def advance(seq: int) -> None:
        engine.advance(time.time(), 0.02)

    def publish(seq: int) -> None:
        robot.publish_frame(time.time(), seq, positions, body_names)

    def close() -> dict[str, int]:
        counted = dict(robot.stats)
        floor_publisher.undeclare()
        robot.stop()
        session.close()
        return counted

    encoder = codec.FrameEncoder(body_names)
    return {"floor": floor, "advance": advance, "encode": lambda seq: encoder.encode(time.time(), seq, positions),
            "put": lambda seq: publishers._frame.put(payload), "publish": publish, "sim": tick}, close


def segments(endpoint: str, n: int) -> None:
    """Under callgrind: each contender on ``n`` frames after ``n`` others, ``os.getppid``
    before each and at the end, the collector off (its passes depend on the heap)."""
    calls, close = contenders(endpoint)
    for call in calls.values():
        for seq in range(n):
            call(seq)
    gc.collect()
    gc.disable()
    for call in calls.values():
        os.getppid()
        for seq in range(n, 2 * n):
            call(seq)
    os.getppid()
    gc.enable()
    stats = close()
    print(f"sim counters: {stats}", file=sys.stderr)
    if stats.get("sent") != 2 * n * 2:  # (publish and sim each publish 2n frames)
        raise SystemExit(f"the sim did not publish every frame: {stats}")


def instructions(n: int) -> dict[str, float]:
    """Instructions per frame of each contender, counted in one process under callgrind."""
    import zenoh
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    anchor = zenoh.open(zenoh_config(listen=endpoint))
    done, fed = CONTEXT.Event(), CONTEXT.Event()
    takers = CONTEXT.Process(target=takers_of, args=(endpoint, FRAME_TAKERS, fed, done), daemon=True)
    takers.start()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "callgrind.out"
            run = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                                  "--dump-before=os_getppid", "--separate-threads=yes", sys.executable, __file__,
                                  "--segments", endpoint, str(n)],
                                 capture_output=True, text=True, cwd=Path(__file__).parent, timeout=900)
            if run.returncode:
                raise SystemExit(f"callgrind run failed:\n{run.stderr[-3000:]}")
            main = list(Path(tmp).glob("callgrind.out.*-01"))  # (the main thread's dumps)
            main.sort(key=lambda path: int(path.name.rsplit(".", 1)[1].split("-")[0]))
            totals = [int(re.search(r"^(?:summary|totals): (\d+)", path.read_text(), re.M).group(1))
                      for path in main]
    finally:
        done.set()
        takers.join(10)
        if takers.is_alive():
            takers.kill()
        anchor.close()
    # dump 1 is the setup and warm-up; then one per contender, each ended by the next getppid
    return {name: total / n for name, total in zip(CONTENDERS, totals[1:], strict=False)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500,
                        help="frames counted per contender (deterministic counts: more only takes longer)")
    parser.add_argument("--name", default="sim_instructions", help="results file name")
    parser.add_argument("--segments", nargs=2, help=argparse.SUPPRESS)  # (the run under callgrind)
    args = parser.parse_args()
    if args.segments:
        segments(args.segments[0], int(args.segments[1]))
        return
    counts = instructions(args.frames)
    print(", ".join(f"{name} {count / 1000:,.1f}k" for name, count in counts.items())
          + f"; sim {counts['sim'] / counts['floor']:.2f}× floor", flush=True)
    summary = [{"scenario": f"(sim) instructions per frame, Pepper with idle motion, {FRAME_TAKERS} takers",
                "sonibus": f"{counts['sim'] / 1000:,.0f}k (advance {counts['advance'] / 1000:,.0f}k, publish_frame "
                           f"{counts['publish'] / 1000:,.0f}k)",
                "baseline": f"floor {counts['floor'] / 1000:,.0f}k", "ratio": f"{counts['sim'] / counts['floor']:.2f}×",
                "goal": "", "met": ""}]
    write(args.name, {"tree": os.path.dirname(os.path.dirname(__import__("sonibus.bus").bus.__file__)),
                      "frames": args.frames, "takers": FRAME_TAKERS, "per_frame": counts, "summary": summary})


if __name__ == "__main__":
    main()
