"""ROS 2 publish → OSC out: the rate achieved, loss and latency of the ``ros2`` adapter's
path beside the naoqi adapter's, in the same run.

- ROS 2: a process publishes ``sensor_msgs/JointState`` as a ROS 2 robot on rmw_zenoh
  does (rosbags encodes it, zenoh-ext's serializer makes the attachment, the header
  stamped just before), paced at ``--rates``, with ``--joints``; a ``sonibus run``
  process (the ``ros2`` node, from a URDF of that many joints, and an OSC sink) connects
  to it. Latency: header stamp → OSC arrival. Loss: of the joint values the messages
  published in the measured window carried, those that never arrived as OSC.
- NAOqi: the fake NAOqi endpoint (a real libqi server, its own process) with Pepper's
  17 joints, read by the ``naoqi`` node at the same rates, in the same kind of
  ``sonibus run`` process. Latency: the frame's ``t`` (its read) → OSC arrival. Loss:
  of the joint values in the frames the adapter put on the bus in the window (a
  subscriber here sees them), those that never arrived as OSC.

A receiver process (plain UDP, not sonibus) takes every OSC message, whose last two
arguments are the frame's ``t`` and ``seq`` (the sink's ``extra``). The first frames
(processes starting, sessions connecting) are not measured. One host, one clock.

    .venv/bin/python bench/ros2_rate.py [--rates 100 50] [--joints 7 17] [--seconds 6]

Writes bench/results/ros2_rate.json and prints a table with the ratios ROS 2 / NAOqi.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common import free_port, latency_stats, write

SONIBUS = str(Path(sys.executable).with_name("sonibus"))
WARMUP_S = 1.0  # after the first OSC message arrives: not measured
NAOQI_JOINTS = 17  # Pepper's


def receive(port: int, flowing: Any, stop: Any, out: Any) -> None:
    """(address, t, seq, arrival) of every OSC message, until ``stop``."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(0.2)
    records = []
    while not stop.is_set():
        try:
            data = sock.recv(2048)
        except TimeoutError:
            continue
        now = time.time()
        t, seq = struct.unpack(">di", data[-12:])
        records.append((data[:data.index(b"\0")].decode(), t, seq, now))
        flowing.set()
    out.put(records)


def urdf(joints: int) -> str:
    """A chain of ``joints`` revolute joints j0, j1, ..."""
    links = "".join(f'<link name="l{i}"/>' for i in range(joints + 1))
    chain = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
                    '<origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>'
                    '<limit lower="-3" upper="3" velocity="1" effort="10"/></joint>' for i in range(joints))
    return f'<?xml version="1.0"?><robot name="bench_{joints}">{links}{chain}</robot>'


def publish_ros(endpoint: str, joints: int, rate: float, seconds: float, flowing: Any, ready: Any,
                out: Any) -> None:
    """A ROS 2 robot's JointState publisher on rmw_zenoh; puts the stamps (s) it published
    in the measured window: from WARMUP_S after the first OSC arrives, for ``seconds``."""
    import threading

    import numpy as np
    from rosbags.typesys import Stores, get_typestore
    from zenoh.ext import Int64, z_serialize

    from sonibus.bus.pacing import Pacer
    from sonibus.bus.session import BusConfig, open_session

    store = get_typestore(Stores.ROS2_JAZZY)
    T, kind = store.types, "sensor_msgs/msg/JointState"
    session = open_session(BusConfig(listen=(endpoint,), multicast=False))
    publisher = session.declare_publisher(
        f"0/joint_states/sensor_msgs::msg::dds_::JointState_/{store.hash_rihs01(kind)}")
    names, gid = [f"j{i}" for i in range(joints)], bytes(range(16))
    ready.set()
    measured: list[float] = []
    sent: list[int] = []
    window: list[float] = []  # [start, end] on this clock, once the chain flows
    stop = threading.Event()

    def tick(n: int) -> None:
        now = time.time()
        if not window and flowing.is_set():
            window[:] = [now + WARMUP_S, now + WARMUP_S + seconds]
        if window and now >= window[1]:
            stop.set()
            return
        sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
        values = np.sin(np.arange(joints) + n * 0.01)
        payload = store.serialize_cdr(T[kind](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                            frame_id=""),
            name=names, position=values, velocity=np.zeros(joints), effort=np.zeros(0)), kind)
        sent.append(n)  # (rmw_zenoh's sequence numbers count what was published: the pacer's skips are no gap)
        publisher.put(bytes(payload), attachment=z_serialize((Int64(len(sent)), Int64(time.time_ns()), gid)).to_bytes())
        if window and now >= window[0]:
            measured.append(sec + nanosec * 1e-9)  # (the adapter's float of the stamp, to the bit)

    Pacer(rate).run(tick, stop)
    time.sleep(0.5)  # the last messages on their way
    publisher.undeclare()
    session.close()
    out.put(measured)


def run_path(config: str, start_source: Any, joints: int, seconds: float, context: Any) -> dict[str, Any]:
    """Receiver, source and ``sonibus run``: what arrived, and the source's own record."""
    port = free_port(socket.SOCK_DGRAM)
    flowing, stop, out = context.Event(), context.Event(), context.Queue()
    receiver = context.Process(target=receive, args=(port, flowing, stop, out))
    receiver.start()
    folder = Path(tempfile.mkdtemp())
    (folder / "robot.urdf").write_text(urdf(joints))
    (folder / "bench.toml").write_text(config.format(port=port, urdf=folder / "robot.urdf"))
    source, published = start_source(flowing)
    log = (folder / "sonibus.log").open("w")
    node = subprocess.Popen([SONIBUS, "-v", "run", str(folder / "bench.toml")], stdout=subprocess.DEVNULL, stderr=log)
    try:
        if not flowing.wait(30):
            sys.exit(f"no OSC within 30 s of starting {folder / 'bench.toml'}")
        started = time.time()
        load = os.getloadavg()[0]
        record = published()
        if record is None:  # (NAOqi: the window is kept here)
            time.sleep(WARMUP_S + seconds + 0.5)
            record = [started + WARMUP_S, started + WARMUP_S + seconds]
    finally:
        node.send_signal(signal.SIGINT)
        node.wait(10)
        stop.set()
        source()
    records = out.get(timeout=30)
    receiver.join(10)
    log.close()
    return {"records": records, "record": record, "load": load, "counters": counters(folder / "sonibus.log")}


def counters(log: Path) -> dict[str, dict[str, int]]:
    """Each node's counters as it said them when it stopped (where a loss happened: the
    robot node's ``dropped``, the sink's ``stale``...)."""
    said = {}
    for line in log.read_text().splitlines():
        if ": stopping; " in line:
            name, _, rest = line.partition(": stopping; ")
            said[name.rsplit(" ", 1)[-1]] = {k: int(v) for k, v in (f.split(" ") for f in rest.split(", "))
                                             if v.isdigit()}
    return said


def ros2_run(joints: int, rate: float, seconds: float, context: Any) -> dict[str, Any]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = (f'[bus]\nmulticast = false\nconnect = ["{endpoint}"]\n\n'
              '[nodes.arm]\nadapter = "ros2"\nrobot = "arm"\nurdf = "{urdf}"\n'
              f'rate_hz = {rate:g}\n\n'
              '[nodes.sound]\nadapter = "osc"\nsubscribe = "arm/joints/*"\n'
              'targets = ["127.0.0.1:{port}"]\nextra = ["t", "seq"]\n')
    stamps = context.Queue()
    process: list[Any] = []

    def start(flowing: Any) -> tuple[Any, Any]:
        ready = context.Event()
        process.append(context.Process(target=publish_ros, args=(endpoint, joints, rate, seconds, flowing, ready,
                                                                 stamps)))
        process[0].start()
        if not ready.wait(30):
            sys.exit("the ROS 2 publisher did not start")
        return lambda: process[0].join(10), lambda: stamps.get(timeout=seconds + 60)

    got = run_path(config, start, joints, seconds, context)
    published = set(got["record"])
    arrived = [r for r in got["records"] if r[1] in published]
    frames = {r[1] for r in arrived}
    wanted = len(published) * joints
    return {"path": "ros2", "joints": joints, "rate_hz": rate, "load_1min": got["load"], "counters": got["counters"],
            "published": len(published), "frames": len(frames), "achieved_hz": len(frames) / seconds,
            "lost_values": wanted - len(arrived), "loss": 1 - len(arrived) / wanted if wanted else 1.0,
            **latency_stats([r[3] - r[1] for r in arrived])}


def naoqi_run(rate: float, seconds: float, context: Any) -> dict[str, Any]:
    from naoqi_rate import serve_fake  # the fake NAOqi endpoint's process, as bench/naoqi_rate.py runs it

    from sonibus.bus import Bus, BusConfig, decode, open_session

    url, endpoint = f"tcp://127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    config = (f'[bus]\nmulticast = false\nconnect = ["{endpoint}"]\n\n'
              f'[nodes.pepper]\nadapter = "naoqi"\nrobot = "pepper"\nurl = "{url}"\nrate_hz = {rate:g}\n'
              'audio = false\n\n'
              '[nodes.sound]\nadapter = "osc"\nsubscribe = "pepper/joints/*"\n'
              'targets = ["127.0.0.1:{port}"]\nextra = ["t", "seq"]\n')
    session = open_session(BusConfig(listen=(endpoint,), multicast=False))
    subscriber, frames = Bus(session, node="bench").subscribe("pepper/frame", maxlen=1_000_000)
    process: list[Any] = []

    def start(_flowing: Any) -> tuple[Any, Any]:
        ready, stop = context.Event(), context.Event()
        process.append(context.Process(target=serve_fake, args=(url, 0.0, ready, stop), daemon=True))
        process[0].start()
        if not ready.wait(30):
            sys.exit("the fake NAOqi endpoint did not start")
        return lambda: (stop.set(), process[0].join(10)), lambda: None

    try:
        got = run_path(config, start, NAOQI_JOINTS, seconds, context)
    finally:
        subscriber.undeclare()
        session.close()
    start_t, end_t = got["record"]
    published = set()  # the frames the adapter put on the bus in the window (its pacer skips some when late)
    while (item := frames.get(timeout=0)) is not None:
        t = decode(item[1])["t"]
        if start_t <= t < end_t:
            published.add(t)
    arrived = [r for r in got["records"] if r[1] in published]
    wanted = len(published) * NAOQI_JOINTS
    return {"path": "naoqi", "joints": NAOQI_JOINTS, "rate_hz": rate, "load_1min": got["load"],
            "counters": got["counters"],
            "published": len(published), "frames": len({r[1] for r in arrived}),
            "achieved_hz": len({r[1] for r in arrived}) / seconds, "lost_values": wanted - len(arrived),
            "loss": 1 - len(arrived) / wanted if wanted else 1.0, **latency_stats([r[3] - r[1] for r in arrived])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 50.0])
    parser.add_argument("--joints", type=int, nargs="+", default=[7, 17])
    parser.add_argument("--seconds", type=float, default=6.0)
    args = parser.parse_args()
    context = multiprocessing.get_context("spawn")
    runs, summary = [], []
    for rate in args.rates:
        naoqi = naoqi_run(rate, args.seconds, context)
        runs.append(naoqi)
        for joints in args.joints:
            ros = ros2_run(joints, rate, args.seconds, context)
            ros["ratio_p50"], ros["ratio_p99"] = ros["p50_us"] / naoqi["p50_us"], ros["p99_us"] / naoqi["p99_us"]
            ros["ratio_rate"] = ros["achieved_hz"] / naoqi["achieved_hz"]
            runs.append(ros)
            summary.append({
                "scenario": f"ROS 2 JointState {joints} joints × {rate:g} Hz → OSC (rmw_zenoh), p50 / p99",
                "sonibus": f"{ros['p50_us'] / 1000:.2f} / {ros['p99_us'] / 1000:.2f} ms, "
                           f"{ros['achieved_hz']:.1f}/s, loss {ros['loss']:.2%}",
                "baseline": f"{naoqi['p50_us'] / 1000:.2f} / {naoqi['p99_us'] / 1000:.2f} ms, "
                            f"{naoqi['achieved_hz']:.1f}/s, loss {naoqi['loss']:.2%} (NAOqi, 17 joints)",
                "ratio": f"{ros['ratio_p50']:.1f}× / {ros['ratio_p99']:.1f}×", "goal": "", "met": ""})
    print(f"{'path':<6} {'joints':>6} {'Hz':>5} {'sent/s':>7} {'achieved':>9} {'loss':>7} {'p50 ms':>8} {'p99 ms':>8} "
          f"{'load':>5}  ROS 2 / NAOqi p50, p99, rate")
    for r in runs:
        ratios = (f"  {r['ratio_p50']:.2f}, {r['ratio_p99']:.2f}, {r['ratio_rate']:.2f}" if r["path"] == "ros2"
                  else "")
        print(f"{r['path']:<6} {r['joints']:>6} {r['rate_hz']:>5g} {r['published'] / args.seconds:>7.1f} "
              f"{r['achieved_hz']:>9.1f} {r['loss']:>7.2%} "
              f"{r['p50_us'] / 1000:>8.2f} {r['p99_us'] / 1000:>8.2f} {r['load_1min']:>5.1f}{ratios}")
        if r["lost_values"]:
            said = {f"{node} {k}": v for node, c in r["counters"].items() for k, v in c.items()
                    if k in ("dropped", "stale", "bad", "ros_lost") and v}
            print(f"       (lost: {said or 'no node counted a drop'})")
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    print(write("ros2_rate", {"seconds": args.seconds, "machine": machine, "runs": runs, "summary": summary}))


if __name__ == "__main__":
    main()
