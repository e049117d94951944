"""Latency from the simulator's acquisition time to liblo's oscdump, beside a
no-bus baseline measured in the same run.

sonibus path: `sonibus demo` (sim → bus → OSC sink, one process) sends to
oscdump; this script also subscribes to the bus and matches each OSC message
to its sample by joint and value, so latency = oscdump's receive time − `t`.
Baseline: this script sends the same messages straight to oscdump with
python-osc; latency = receive time − send time.

    .venv/bin/python bench/sim_to_oscdump.py [--seconds 10] [--rate 100]

Writes bench/results/sim_to_oscdump.json and prints a table.
"""

from __future__ import annotations

import argparse
import re
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

from common import compare, free_port, latency_stats, write
from pythonosc.udp_client import SimpleUDPClient

from sonibus.bus import Bus, BusConfig, decode, open_session

NTP_EPOCH = 2208988800
LINE = re.compile(r"^([0-9a-f]{8})\.([0-9a-f]{8}) (\S+) f (\S+)$")


def as_float32_text(value: float) -> str:
    return f"{struct.unpack('f', struct.pack('f', value))[0]:f}"


class OscDump:
    """oscdump in a child process; lines as (receive time, address, value text)."""

    def __init__(self, port: int) -> None:
        self.proc = subprocess.Popen(["oscdump", "-L", str(port)], stdout=subprocess.PIPE, text=True)
        self.received: list[tuple[float, str, str]] = []
        threading.Thread(target=self._read, daemon=True).start()
        time.sleep(0.3)

    def _read(self) -> None:
        for line in self.proc.stdout:
            m = LINE.match(line.strip())
            if m:
                t = int(m[1], 16) - NTP_EPOCH + int(m[2], 16) / 2**32
                self.received.append((t, m[3], m[4]))

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(5)


def sonibus_path(seconds: float, rate: float) -> dict[str, float]:
    port, zport = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_STREAM)
    dump = OscDump(port)
    demo = subprocess.Popen([str(Path(sys.executable).with_name("sonibus")), "demo", "--quiet", "--no-multicast",
                             "--listen", f"tcp/127.0.0.1:{zport}", "--port", str(port), "--rate", str(rate)],
                            stdout=subprocess.DEVNULL)
    sent: dict[tuple[str, str], list[float]] = {}
    frames: dict[int, float] = {}
    time.sleep(1.0)
    with open_session(BusConfig(multicast=False, connect=(f"tcp/127.0.0.1:{zport}",))) as session:
        subscriber, queue = Bus(session).subscribe("pepper/joints/*", 1 << 20)
        time.sleep(0.5)
        start = len(dump.received)
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            item = queue.get(timeout=0.1)
            if item:
                key, payload = item
                sample = decode(payload)
                frames[sample["seq"]] = sample["t"]
                joint = key.rsplit("/", 1)[1]
                sent.setdefault((f"/pepper/joints/{joint}", as_float32_text(sample["v"])), []).append(sample["t"])
        subscriber.undeclare()
    demo.send_signal(2)
    demo.wait(5)
    time.sleep(0.2)
    dump.close()
    latencies = []
    received = dump.received[start:]
    for t_recv, address, value in received:
        times = sent.get((address, value))
        if times and len(times) == 1:  # only values seen once: unambiguous
            latencies.append(t_recv - times[0])
    first, last = min(frames), max(frames)
    result = latency_stats(latencies)
    result["rate_frames_per_s"] = (len(frames) - 1) / (frames[last] - frames[first])
    result["frames_missing_in_seq"] = last - first + 1 - len(frames)
    return result


def baseline(seconds: float, rate: float) -> dict[str, float]:
    port = free_port(socket.SOCK_DGRAM)
    dump = OscDump(port)
    client = SimpleUDPClient("127.0.0.1", port)
    sent: dict[tuple[str, str], float] = {}
    period = 1.0 / rate
    start = time.monotonic()
    frame = 0
    while time.monotonic() - start < seconds:
        for j in range(17):
            value = frame * 1e-3 + j * 10.0
            address = f"/pepper/joints/J{j}"
            sent[(address, as_float32_text(value))] = time.time()
            client.send_message(address, value)
        frame += 1
        time.sleep(max(0.0, start + frame * period - time.monotonic()))
    time.sleep(0.3)
    dump.close()
    latencies = [t - sent[(a, v)] for t, a, v in dump.received if (a, v) in sent]
    return latency_stats(latencies)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=100.0)
    args = parser.parse_args()
    base = baseline(args.seconds, args.rate)
    bus = sonibus_path(args.seconds, args.rate)
    result = {"rate_hz": args.rate, "seconds": args.seconds, "baseline_no_bus": base, "sonibus": bus}
    compare(result, base, bus, ["n", "p50_us", "p99_us", "p999_us"])
    write("sim_to_oscdump", result)
    print(f"sonibus frame rate {bus['rate_frames_per_s']:.1f}/s, {bus['frames_missing_in_seq']} frames missing")


if __name__ == "__main__":
    main()
