"""The cost per frame of decoding a ROS 2 ``sensor_msgs/JointState`` (CDR) beside the
bus's own msgpack frame: our decoder (adapters/ros2/cdr.py), rosbags' generic one, and
``codec.decode`` of the frame the adapter publishes for it.

    .venv/bin/python bench/ros2_cdr.py [--joints 7 17 50] [--n 20000]

Writes bench/results/ros2_cdr.json and prints a table (µs per message, median of 5 runs).
"""

from __future__ import annotations

import argparse
import statistics
import time

from common import write
from rosbags.typesys import Stores, get_typestore

from sonibus.adapters.ros2 import cdr
from sonibus.bus import codec, messages

STORE = get_typestore(Stores.ROS2_JAZZY)


def per_call_us(function, payload: bytes, n: int) -> float:
    runs = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(n):
            function(payload)
        runs.append((time.perf_counter() - start) / n * 1e6)
    return statistics.median(runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--joints", type=int, nargs="+", default=[7, 17, 50])
    parser.add_argument("--n", type=int, default=20000)
    args = parser.parse_args()
    rows = []
    for count in args.joints:
        names = [f"joint_{i}" for i in range(count)]
        values = [0.1 * i for i in range(count)]
        payload = cdr.joint_state(cdr.Stamp(1_763_900_000, 5), names, values, values, values)
        frame = codec.encode(messages.frame(1_763_900_000.0, 1, names, values))
        row = {"joints": count, "bytes_cdr": len(payload), "bytes_msgpack": len(frame),
               "ours_us": per_call_us(cdr.read_joint_state, payload, args.n),
               "rosbags_us": per_call_us(lambda p: STORE.deserialize_cdr(p, "sensor_msgs/msg/JointState"),
                                         payload, args.n),
               "msgpack_frame_us": per_call_us(codec.decode, frame, args.n)}
        rows.append(row)
        print(f"{count:>3} joints: ours {row['ours_us']:6.2f} µs, rosbags {row['rosbags_us']:6.2f} µs, "
              f"msgpack frame {row['msgpack_frame_us']:6.2f} µs ({len(payload)} / {len(frame)} bytes)")
    print(write("ros2_cdr", {"rows": rows}))


if __name__ == "__main__":
    main()
