"""What the benchmark scripts share: free ports, Zenoh configs, OSC datagrams taken apart,
latency statistics, results."""

from __future__ import annotations

import json
import os
import random
import socket
import struct
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A port free now on 127.0.0.1, below Linux's ephemeral range (32768 and up): a port the OS
    gave out (bind to 0) was taken again, before the node it was for listened on it, by another
    process's own bind to 0 or outgoing connection (the show's Foxglove node, once)."""
    for _ in range(200):
        port = random.randrange(20000, 32768)
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def lease_ms() -> int:
    """The Zenoh lease of the benchmarks' own sessions: sonibus's (``[bus] lease_ms``), or
    ``BENCH_LEASE_MS`` (``show.py --lease-ms``: its nodes' and floors' alike). A floor at
    Zenoh's default (10 s) sent a keep-alive on each idle link every 2.5 s where sonibus's
    sessions send one every 375 ms: work a node must do (a lost robot noticed within 2 s) that
    its floor did not."""
    from sonibus.bus.busconfig import BusConfig
    return int(os.environ.get("BENCH_LEASE_MS") or BusConfig.lease_ms)


def zenoh_config(extra: dict[str, Any] | None = None, **endpoints: str) -> Any:
    """A zenoh-python config without sonibus: multicast scouting off, sonibus's lease
    (``lease_ms``), ``listen=`` / ``connect=`` an endpoint each, and ``extra`` options
    (key → value, as JSON5)."""
    import zenoh
    config = zenoh.Config()
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("transport/link/tx/lease", str(lease_ms()))
    for side, endpoint in endpoints.items():
        config.insert_json5(f"{side}/endpoints", json.dumps([endpoint]))
    for key, value in (extra or {}).items():
        config.insert_json5(key, json.dumps(value))
    return config


def osc_messages(data: bytes) -> list[bytes]:
    """The OSC messages of a datagram: itself, or a bundle's elements."""
    if not data.startswith(b"#bundle\0"):
        return [data]
    out, at = [], 16
    while at < len(data):
        size = struct.unpack(">i", data[at:at + 4])[0]
        out.append(data[at + 4:at + 4 + size])
        at += 4 + size
    return out


def latency_stats(seconds: list[float]) -> dict[str, float]:
    """Median, p99, p99.9 and max of latencies given in seconds, in µs."""
    a = np.array(seconds) * 1e6
    return {"n": len(a), "p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
            "p999_us": float(np.percentile(a, 99.9)), "max_us": float(a.max())}


def write(name: str, result: dict[str, Any]) -> Path:
    """``bench/results/<name>.json``."""
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(result, indent=2) + "\n")
    return path


def compare(result: dict[str, Any], base: dict[str, Any], bus: dict[str, Any], columns: list[str]) -> None:
    """Add the p50/p99 ratios to ``result`` and print both rows and the ratios."""
    result["ratio_p50"] = bus["p50_us"] / base["p50_us"]
    result["ratio_p99"] = bus["p99_us"] / base["p99_us"]
    print(f"{'path':<9} " + " ".join(f"{c:>9}" for c in columns))
    for name, row in (("no bus", base), ("sonibus", bus)):
        print(f"{name:<9} " + " ".join(f"{row[c]:>9.0f}" for c in columns))
    print(f"ratio p50 {result['ratio_p50']:.2f}, p99 {result['ratio_p99']:.2f}")


def callgrind_totals(argv: list[str], cwd: Path) -> list[int]:
    """Run ``argv`` (a Python script) under ``valgrind --tool=callgrind``, its counts dumped whenever
    ``os.getppid`` is entered: the main thread's instructions of each dump, in order (the first:
    from the start to the first ``os.getppid``). ``SystemExit`` with valgrind's end if it failed."""
    import re
    import subprocess
    import sys
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        run = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                              "--dump-before=os_getppid", "--separate-threads=yes", sys.executable, *argv],
                             capture_output=True, text=True, cwd=cwd)
        if run.returncode:
            raise SystemExit(f"callgrind run failed:\n{run.stderr[-3000:]}")
        main = [path for path in Path(tmp).glob("callgrind.out.*-01")]  # (the main thread's dumps)
        main.sort(key=lambda path: int(path.name.rsplit(".", 1)[1].split("-")[0]))
        return [int(re.search(r"^(?:summary|totals): (\d+)", path.read_text(), re.M).group(1)) for path in main]


def counted_calls(calls: list[Any], warm: list[Any], counted: list[Any]) -> None:
    """Under ``callgrind_totals``: each of ``calls`` on every item of ``warm``, then, the collector
    off (its passes depend on the heap), each on every item of ``counted``, ``os.getppid`` before
    each and after the last (a dump each: ``len(calls)`` of them, and one more at the end)."""
    import gc
    import os
    for call in calls:
        for item in warm:
            call(item)
    gc.collect()
    gc.disable()
    try:
        for call in calls:
            os.getppid()
            for item in counted:
                call(item)
        os.getppid()
    finally:
        gc.enable()
