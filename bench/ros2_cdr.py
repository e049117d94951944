"""The cost per message of ROS 2 CDR beside the bus's own msgpack frame: decoding a
``sensor_msgs/JointState`` with our decoder (adapters/ros2/cdr.py) and with rosbags'
generic one, ``codec.decode`` of the frame the adapter publishes for it, and encoding
a one-point ``trajectory_msgs/JointTrajectory`` (what ``joints/set`` sends) both ways.

Seconds: batches of ``--batch`` calls, the contenders taking turns batch by batch (so a
load that comes and goes weighs on all alike); median and p99 of the per-call time over
the batches, and each one's ratio to rosbags'. Instructions (``--instructions``): each
contender ``--n`` times in turn under ``valgrind --tool=callgrind``, counted apart (the loop
itself included, about a hundred instructions a call): deterministic, whatever the load.

    .venv/bin/python bench/ros2_cdr.py [--joints 7 17 50] [--batches 300] [--instructions 17]

Writes bench/results/ros2_cdr.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from common import write
from rosbags.typesys import Stores, get_typestore

from sonibus.adapters.ros2 import cdr
from sonibus.bus import codec, framing

STORE = get_typestore(Stores.ROS2_JAZZY)
JOINT_STATE, TRAJECTORY = "sensor_msgs/msg/JointState", "trajectory_msgs/msg/JointTrajectory"


def contenders(joints: int) -> dict[str, tuple[Callable[[], object], str]]:
    """name → (one call, what it is): the same message for all."""
    names = [f"joint_{i}" for i in range(joints)]
    values = [0.1 * i for i in range(joints)]
    payload = cdr.joint_state(cdr.Stamp(1_763_900_000, 5), names, values, values, values)
    frame = codec.encode(framing.frame(1_763_900_000.0, 1, names, values))
    T = STORE.types
    point = [cdr.Point(values, 1.5, [0.0] * joints)]

    def rosbags_trajectory() -> bytes:
        return bytes(STORE.serialize_cdr(T[TRAJECTORY](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""),
            joint_names=names, points=[T["trajectory_msgs/msg/JointTrajectoryPoint"](
                positions=np.array(values), velocities=np.zeros(joints), accelerations=np.zeros(0),
                effort=np.zeros(0), time_from_start=T["builtin_interfaces/msg/Duration"](sec=1, nanosec=500_000_000))
            ]), TRAJECTORY))

    assert rosbags_trajectory() == cdr.joint_trajectory(cdr.Stamp(0, 0), names, point)  # the same bytes
    return {
        "decode_ours": (lambda: cdr.read_joint_state(payload), f"JointState, {len(payload)} B"),
        "decode_rosbags": (lambda: STORE.deserialize_cdr(payload, JOINT_STATE), "JointState"),
        "decode_msgpack_frame": (lambda: codec.decode(frame), f"the bus frame, {len(frame)} B"),
        "encode_ours": (lambda: cdr.joint_trajectory(cdr.Stamp(0, 0), names, point), "JointTrajectory, 1 point"),
        "encode_rosbags": (rosbags_trajectory, "JointTrajectory, message built and serialized"),
    }


def seconds(joints: int, batches: int, batch: int) -> dict[str, dict[str, float]]:
    """Median and p99 µs per call, batch by batch, the contenders taking turns."""
    calls = contenders(joints)
    times: dict[str, list[float]] = {name: [] for name in calls}
    clock = time.perf_counter
    for _ in range(batches):
        for name, (call, _what) in calls.items():
            start = clock()
            for _ in range(batch):
                call()
            times[name].append((clock() - start) / batch * 1e6)
    return {name: {"p50_us": float(np.median(t)), "p99_us": float(np.percentile(t, 99))} for name, t in times.items()}


def instructions(joints: int, n: int) -> dict[str, float]:
    """Instructions per call of each contender: one process under callgrind, which dumps its
    counts (and starts afresh) whenever ``os.getppid`` is entered, called between contenders."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", "--dump-before=os_getppid",
                        sys.executable, __file__, "--segments", str(joints), str(n)],
                       capture_output=True, text=True, cwd=Path(__file__).parent, check=True)
        dumps = sorted(Path(tmp).glob("callgrind.out.*"), key=lambda path: int(path.name.rsplit(".", 1)[1]))
        totals = [int(re.search(r"^(?:summary|totals): (\d+)", d.read_text(), re.M).group(1)) for d in dumps]
    # dump 1 is the setup; then one per contender, each ended by the next getppid
    return {name: total / n for name, total in zip(contenders(joints), totals[1:], strict=False)}


def segments(joints: int, n: int) -> None:
    """Under callgrind: ``n`` calls of each contender in turn after one each, ``os.getppid``
    before each and at the end, the collector off (its passes depend on the heap, not the
    contender)."""
    calls = contenders(joints)
    for call, _what in calls.values():  # (rosbags' first call of a type does work once: not counted)
        call()
    gc.collect()
    gc.disable()
    for call, _what in calls.values():
        os.getppid()
        for _ in range(n):
            call()
    os.getppid()


def summary(row: dict[str, Any]) -> list[dict[str, str]]:
    """docs/performance.md's rows (bench/run.py) for one message size."""
    s, n, out = row["seconds"], row["joints"], []
    for kind, what in (("decode", "JointState decode"), ("encode", "JointTrajectory encode")):
        ours, theirs = s[f"{kind}_ours"], s[f"{kind}_rosbags"]
        counted = row.get("instructions")
        base = f"{theirs['p50_us']:.1f} / {theirs['p99_us']:.1f} µs (rosbags)"
        if kind == "decode":
            base += f"; msgpack of our frame {s['decode_msgpack_frame']['p50_us']:.1f} µs"
        ratio = f"{row[f'{kind}_ratio_p50']:.2f}× / {row[f'{kind}_ratio_p99']:.2f}×"
        if counted:
            ratio += f"; {row[f'{kind}_ratio_instructions']:.2f}× instructions"
        out.append({"scenario": f"ROS 2 {what}, {n} joints, µs p50 / p99",
                    "sonibus": f"{ours['p50_us']:.1f} / {ours['p99_us']:.1f} µs"
                               + (f" ({counted[f'{kind}_ours'] / 1000:.0f}k instructions)" if counted else ""),
                    "baseline": base, "ratio": ratio, "goal": "< 1× rosbags",
                    "met": "yes" if row[f"{kind}_ratio_p50"] < 1 else "no"})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--joints", type=int, nargs="+", default=[7, 17, 50])
    parser.add_argument("--batches", type=int, default=300)
    parser.add_argument("--batch", type=int, default=20)
    parser.add_argument("--instructions", type=int, nargs="*", default=[], metavar="JOINTS",
                        help="also count instructions with callgrind, for these of --joints")
    parser.add_argument("--n", type=int, default=1000, help="calls per contender under callgrind")
    parser.add_argument("--segments", nargs=2, type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.segments:
        return segments(*args.segments)
    rows = []
    for joints in args.joints:
        row = {"joints": joints, "load_1min": os.getloadavg()[0], "seconds": seconds(joints, args.batches, args.batch)}
        s = row["seconds"]
        for kind in ("decode", "encode"):
            for q in ("p50", "p99"):
                row[f"{kind}_ratio_{q}"] = s[f"{kind}_ours"][f"{q}_us"] / s[f"{kind}_rosbags"][f"{q}_us"]
        print(f"{joints:>3} joints (load {row['load_1min']:.1f}), µs per call p50 / p99:")
        for name, (_call, what) in contenders(joints).items():
            print(f"    {name:<21} {s[name]['p50_us']:7.2f} / {s[name]['p99_us']:7.2f}   {what}")
        print(f"    ours / rosbags: decode {row['decode_ratio_p50']:.2f} / {row['decode_ratio_p99']:.2f}, "
              f"encode {row['encode_ratio_p50']:.2f} / {row['encode_ratio_p99']:.2f}")
        if joints in args.instructions:
            row["instructions"] = counts = instructions(joints, args.n)
            row["decode_ratio_instructions"] = counts["decode_ours"] / counts["decode_rosbags"]
            row["encode_ratio_instructions"] = counts["encode_ours"] / counts["encode_rosbags"]
            print("    instructions per call: " + ", ".join(f"{k} {v:,.0f}" for k, v in counts.items()))
        rows.append(row)
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    print(write("ros2_cdr", {"machine": machine, "rows": rows, "summary": [x for r in rows for x in summary(r)]}))


if __name__ == "__main__":
    main()
