"""What the nodes of the show in one process pay to take a robot's frames through their
``Selection`` (the gate's check and the selection: issue 35, ``bus/verdicts.py``), in
instructions a tick, counted by ``valgrind --tool=callgrind``: deterministic, whatever
the load of the machine.

The show's takers, as ``bench/show.py``'s show builds them: the OSC sink, features,
the recorder, the web node, OSCQuery, Foxglove and MIDI, each a ``Selection`` of its
default patterns, all on one process's ``Limits``. Each tick a new robot frame (17
joints) and a new derived frame (the features node's shape, ``floor.DERIVED``) is handed
to every taker of it, as the one Zenoh subscriber of a key hands its bytes
(``Selection.incoming``). The instructions of a run of ``--ticks`` ticks less those of a
run of a fifth as many (Python's start and the imports cancel out), over the ticks between.

    .venv/bin/python bench/verdicts.py [--ticks 1000] [--against DIR]

``--against DIR``: the same on the tree in DIR (``DIR/sonibus/{bus,...}``, as
``show.py --against``). Writes bench/results/verdicts.json and prints a table.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import write
from floor import DERIVED

# (patterns of each node of the show, by their defaults: bench/show.py's SHOW)
TAKERS = {
    "osc": ["pepper/joints/*", "pepper/derived/**", "pepper/events/*"],
    "features": ["pepper/joints/*"],
    "recorder": ["*/joints/*", "*/derived/**", "*/events/*"],
    "web": ["*/joints/*", "*/events/*"],
    "oscquery": ["*/joints/*", "*/derived/**", "*/events/*"],
    "foxglove": ["*/joints/*", "*/derived/**", "*/events/*"],
    "midi": ["*/joints/*", "*/events/*"],
}
JOINTS = 17


def run(ticks: int) -> None:
    """The workload (under callgrind): ``ticks`` frames and derived frames to the show's takers."""
    import math

    import msgpack

    from sonibus.bus.messages import Limits
    from sonibus.bus.streams import Selection

    limits = Limits()
    takers = {node: Selection(patterns, limits) for node, patterns in TAKERS.items()}
    frames = list(takers)
    derived = [node for node, patterns in TAKERS.items() if any("derived" in p for p in patterns)]
    names = [f"J{j}" for j in range(JOINTS)]
    dnames = [name for name, _ in DERIVED]
    t0 = time.time() - 60
    for tick in range(ticks):
        t = t0 + tick * 0.02
        frame = msgpack.packb({"t": t, "seq": tick, "names": names, "v": [math.sin(tick + j) for j in range(JOINTS)]})
        values = [0.1 * tick if size == 1 else [0.1, 0.2, 0.3] for _, size in DERIVED]
        dframe = msgpack.packb({"t": t, "seq": tick, "names": dnames, "v": values})
        for node in frames:
            takers[node].incoming("pepper/frame", frame)
        for node in derived:
            takers[node].incoming("pepper/derived", dframe)


def instructions(ticks: int, tree: str) -> int:
    """Instructions of a whole run of ``ticks`` (all threads), on ``tree`` ("": this one)."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "callgrind.out"
        env = {**os.environ, "PYTHONHASHSEED": "0", **({"PYTHONPATH": tree} if tree else {})}
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", sys.executable,
                        __file__, "--run", str(ticks)], env=env, check=True, capture_output=True)
        summary = re.search(r"^summary: (\d+)", out.read_text(), re.M) or re.search(r"^totals: (\d+)",
                                                                                     out.read_text(), re.M)
        if summary is None:
            raise RuntimeError(f"no totals in {out}")
        return int(summary[1])


def per_tick(ticks: int, tree: str) -> float:
    few = ticks // 5
    return (instructions(ticks, tree) - instructions(few, tree)) / (ticks - few)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=1000)
    parser.add_argument("--against", metavar="DIR", default="")
    parser.add_argument("--name", default="verdicts", help="results file name")
    parser.add_argument("--run", type=int, help=argparse.SUPPRESS)  # (the workload, under callgrind)
    args = parser.parse_args()
    if args.run is not None:
        run(args.run)
        return
    trees = {"this tree": "", **({args.against: args.against} if args.against else {})}
    counts = {label: per_tick(args.ticks, tree) for label, tree in trees.items()}
    for label, count in counts.items():
        print(f"{label}: {count / 1000:.1f}k instructions a tick (a frame and a derived frame to the show's takers)")
    summary = [{"scenario": "(issue 35) the show's takers in one process, a frame and a derived frame a tick: "
                            "instructions a tick (callgrind)",
                "sonibus": f"{counts['this tree'] / 1000:.1f}k",
                "baseline": f"{counts[args.against] / 1000:.1f}k ({args.against})" if args.against else "",
                "ratio": f"{counts['this tree'] / counts[args.against]:.2f}×" if args.against else ""}]
    write(args.name, {"ticks": args.ticks, "takers": TAKERS, "per_tick": counts, "summary": summary})


if __name__ == "__main__":
    main()
