"""Recorder samples/s with no drop, beside the MCAP writer's own ceiling
(issue 9, scenario e).

sonibus path, per step of the ramp: publisher process(es) put frames as a
robot owner does (``RobotAdapter.publish_frame``; ``sink_throughput.publish``):
each frame of 17 joints whole on ``botN/frame`` (``framing.frame``,
``Bus.stream_publisher``), then its samples on ``botN/joints/JK``; the
recorder is its own process (``sonibus run`` with ``adapter = "recorder"``,
``subscribe = ["*/joints/*"]``, so it takes the frames and writes each one
whole, one MCAP message, since issue 35; a fresh file each step, listening on
loopback TCP). Rates and counts are joint samples (a frame of 17 joints is 17,
as ``Recording.message_count`` reads it). When the publishers are done
the recorder is stopped (SIGTERM: it writes what is still queued, then the
summary); the file's message count and the
recorder's ``sonibus.stats`` metadata (``dropped``: its queue was full) say
what was kept: ``lost`` = put − in the file; of it, ``dropped`` went in the
recorder's full queue, the rest never reached the recorder (``received``:
Zenoh's DROP congestion control on the publishers' side when the recorder's
socket reader falls behind). ``written/s`` = messages in the file / time from
the start of the step until the recorder exited. ``drain`` is how long the recorder took to finish after the
publishers ended: a recorder that keeps up finishes in well under a second,
one that fell behind is still emptying its queue (65,536 frames deep, so a
short step can be drop-free without keeping up; ``kept up`` needs both).

Baselines, same run, one process each, as fast as they go: the ``mcap``
library's ``Writer`` adding the same JSON messages (serialized beforehand;
same channels, 1 MB chunks, zstd) — the file format's own ceiling — and
sonibus's ``RecordingWriter.write`` (JSON encoding included), i.e. the
recorder's writing code without the bus.

    .venv/bin/python bench/recorder_rate.py [--rates 10000 20000 40000 60000 80000 100000]
        [--seconds 3] [--robots 4] [--publishers 2]

Writes bench/results/recorder_rate.json and prints a table.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

from common import free_port, write
from sink_throughput import JOINTS, SONIBUS, Publishers, cpu_seconds, stop_process, thread_cpu, thread_share

KEPT_UP_DRAIN_S = 1.0   # a step "kept up" if the recorder was done this soon after the publishers


def messages(robots: int, count: int) -> list[tuple[str, dict[str, Any]]]:
    """``count`` joint samples of ``robots`` robots, frame by frame, as the publishers send them."""
    t0 = time.time()
    out = []
    for n in range(count // (robots * JOINTS) + 1):
        for r in range(robots):
            for j in range(JOINTS):
                out.append((f"bot{r}/joints/J{j}", {"t": t0 + n * 0.01, "seq": n, "v": 0.5 * ((n * 0.01 + j) % 2.0)
                                                    - 0.5}))
    return out[:count]


def mcap_ceiling(folder: Path, robots: int, seconds: float) -> dict[str, float]:
    """The mcap Writer alone: pre-serialized JSON messages added as fast as it goes."""
    from mcap.writer import CompressionType, Writer

    from sonibus import schemas
    from sonibus.adapters.recorder.channels import SCHEMA_ENCODING, SCHEMA_PREFIX, to_json

    data = [(key, int(m["t"] * 1e9), to_json(m)) for key, m in messages(robots, 50_000)]
    path = folder / "mcap-ceiling.mcap"
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=1 << 20, compression=CompressionType.ZSTD)
        writer.start(profile="", library="bench")
        schema = writer.register_schema(SCHEMA_PREFIX + "joint_sample", SCHEMA_ENCODING,
                                        to_json(schemas.load("joint_sample")))
        channels = {key: writer.register_channel(key, "json", schema) for key in dict.fromkeys(k for k, _, _ in data)}
        sequence = dict.fromkeys(channels.values(), 0)
        cpu0, start, written = time.process_time(), time.perf_counter(), 0
        while time.perf_counter() - start < seconds:
            for key, log_ns, payload in data:
                channel = channels[key]
                sequence[channel] += 1
                writer.add_message(channel, log_time=log_ns, data=payload, publish_time=log_ns,
                                   sequence=sequence[channel])
            written += len(data)
        writer.finish()
        elapsed = time.perf_counter() - start
    return {"messages": written, "seconds": elapsed, "per_s": written / elapsed,
            "cpu_percent": 100.0 * (time.process_time() - cpu0) / elapsed, "bytes": path.stat().st_size}


def writer_ceiling(folder: Path, robots: int, seconds: float) -> dict[str, float]:
    """sonibus's RecordingWriter (JSON encoding, channels, chunks flushed and fsync'ed every second)."""
    from sonibus.adapters.recorder.writer import RecordingWriter

    data = messages(robots, 50_000)
    path = folder / "writer-ceiling.mcap"
    cpu0, start, written = time.process_time(), time.perf_counter(), 0
    with RecordingWriter(str(path)) as out:
        while time.perf_counter() - start < seconds:
            for key, message in data:
                out.write(key, time.time_ns(), message)
            written += len(data)
    elapsed = time.perf_counter() - start
    return {"messages": written, "seconds": elapsed, "per_s": written / elapsed,
            "cpu_percent": 100.0 * (time.process_time() - cpu0) / elapsed, "bytes": path.stat().st_size}


def step(rate: float, seconds: float, robots: int, publishers: int, folder: Path) -> dict[str, Any]:
    from sonibus.adapters.recorder import Recording

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    recording = folder / f"step-{rate:g}.mcap"
    config = folder / "recorder.toml"
    config.write_text(f'[bus]\nmulticast = false\n\n[nodes.recorder]\nadapter = "recorder"\npath = "{recording}"\n'
                      f'subscribe = ["*/joints/*"]\nstatus_every_s = 0\n')
    log_path = folder / f"recorder-{rate:g}.log"
    with open(log_path, "w") as log:
        recorder = subprocess.Popen([SONIBUS, "-v", "run", str(config), "--no-multicast", "--listen", endpoint],
                                    stdout=subprocess.DEVNULL, stderr=log, start_new_session=True)
    group = None
    try:
        group = Publishers(endpoint, publishers, robots, rate, seconds)  # frame whole, then per joint
        group.wait_ready(recorder)
        cpu0, threads0, started = cpu_seconds(recorder.pid), thread_cpu(recorder.pid), time.monotonic()
        pub = group.run(timeout=3 * seconds + 30)
        window = time.monotonic() - started
        cpu, threads = cpu_seconds(recorder.pid) - cpu0, thread_share(threads0, thread_cpu(recorder.pid), window)
        time.sleep(0.2)  # what Zenoh still carries
        stop_process(recorder, timeout=60)
        done = time.monotonic()
    finally:
        if group is not None:
            group.close()
        stop_process(recorder)
    if recorder.returncode not in (0, 130):  # 130: ended by the signal, its normal way
        raise RuntimeError(f"the recorder ended with {recorder.returncode}: {log_path.read_text()[-2000:]}")
    with Recording(str(recording)) as found:
        count = found.message_count
        stats = {k: int(v) for k, v in found.metadata.get("sonibus.stats", {}).items()}
    size = recording.stat().st_size
    recording.unlink()
    return {"offered_per_s": rate, "sent": pub["sent"], "achieved_per_s": pub["achieved_per_s"],
            "publisher_cpu_percent": pub["cpu_percent"], "messages_in_file": count,
            "lost": pub["sent"] - count, "dropped": stats.get("dropped", -1), "recorder_stats": stats,
            "drain_s": done - pub["ended"], "written_per_s": count / (done - started),
            "recorder_cpu_percent": 100.0 * cpu / window, "recorder_threads_cpu_percent": threads,
            "bytes": size, "bytes_per_message": size / max(1, count)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[10000, 20000, 40000, 60000, 80000, 100000],
                        help="offered joint samples/s, one step each")
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each step")
    parser.add_argument("--robots", type=int, default=4, help="robots of 17 joints; a batch is one frame of each")
    parser.add_argument("--publishers", type=int, default=2, help="publisher processes sharing the robots")
    parser.add_argument("--baseline-seconds", type=float, default=3.0, help="length of each baseline run")
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    steps: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        ceiling = mcap_ceiling(folder, args.robots, args.baseline_seconds)
        ours = writer_ceiling(folder, args.robots, args.baseline_seconds)
        for rate in args.rates:
            steps.append(step(rate, args.seconds, args.robots, args.publishers, folder))
            print(f"  {rate:>8.0f}/s: {steps[-1]['lost']} lost, {steps[-1]['dropped']} dropped, "
                  f"drain {steps[-1]['drain_s']:.2f} s", flush=True)
    clean = [s for s in steps if s["lost"] == 0 and s["dropped"] == 0]
    kept_up = [s for s in clean if s["drain_s"] <= KEPT_UP_DRAIN_S]
    result = {"joints": JOINTS, "robots": args.robots, "publishers": args.publishers, "seconds": args.seconds,
              "machine": machine, "mcap_writer": ceiling, "recording_writer": ours, "recorder": steps,
              "max_no_drop_per_s": max((s["offered_per_s"] for s in clean), default=0.0),
              "max_kept_up_per_s": max((s["offered_per_s"] for s in kept_up), default=0.0)}
    result["ratio_kept_up_to_mcap"] = result["max_kept_up_per_s"] / ceiling["per_s"]
    top = next((s for s in steps if s["offered_per_s"] == result["max_kept_up_per_s"]), None)
    result["summary"] = [{  # the row of bench/run.py's table
        "scenario": "(e) recorder samples/s, none dropped or lost, kept up",
        "sonibus": f"{result['max_kept_up_per_s']:,.0f}/s" + (f", recorder {top['recorder_cpu_percent']:.0f} % CPU"
                                                              if top else ""),
        "baseline": f"{ceiling['per_s']:,.0f}/s mcap Writer; {ours['per_s']:,.0f}/s RecordingWriter (one process)",
        "ratio": f"{result['ratio_kept_up_to_mcap']:.2f}×"}]
    print(f"{'baseline (one process, unpaced)':<34} {'msgs/s':>8} {'CPU %':>6} {'bytes/msg':>9}")
    for label, row in (("mcap Writer, JSON serialized before", ceiling), ("sonibus RecordingWriter", ours)):
        print(f"{label:<34} {row['per_s']:>8.0f} {row['cpu_percent']:>6.0f} {row['bytes'] / row['messages']:>9.1f}")
    print(f"{'offered/s':>9} {'put/s':>8} {'received':>8} {'in file':>8} {'lost':>7} {'dropped':>7} {'drain s':>7} "
          f"{'written/s':>9} {'rec CPU%':>8} {'py/zrx %':>8} {'pub CPU%':>8}")
    for s in steps:
        threads = s["recorder_threads_cpu_percent"]
        split = f"{threads.get('sonibus', 0):.0f}/{threads.get('rx', 0):.0f}"
        print(f"{s['offered_per_s']:>9.0f} {s['achieved_per_s']:>8.0f} {s['recorder_stats'].get('received', -1):>8} "
              f"{s['messages_in_file']:>8} {s['lost']:>7} "
              f"{s['dropped']:>7} {s['drain_s']:>7.2f} {s['written_per_s']:>9.0f} {s['recorder_cpu_percent']:>8.0f} "
              f"{split:>8} {s['publisher_cpu_percent']:>8.0f}")
    print(f"recorder: no drop up to {result['max_no_drop_per_s']:.0f}/s, kept up (drain ≤ {KEPT_UP_DRAIN_S:g} s) "
          f"up to {result['max_kept_up_per_s']:.0f}/s = {result['ratio_kept_up_to_mcap']:.2f} × the mcap Writer's "
          f"{ceiling['per_s']:.0f}/s")
    write("recorder_rate", result)
    print(machine)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks
    main()
