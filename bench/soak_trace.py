"""``sonibus run CONFIG`` in this process, watched from inside: what ``soak_show.py --trace``
runs instead of ``sonibus run`` to tell Python's growth from native growth, and to
name the lines that allocate what stays.

    .venv/bin/python bench/soak_trace.py CONFIG OUTDIR [--frames 10] [--every 10] [--base-after 300]
        [--report-every 600]

Every ``--every`` s a line of OUTDIR/samples.jsonl: RSS, Python's traced memory
(tracemalloc), the part of it that is samples waiting in the nodes' queues (payloads
allocated by ``Bus.subscribe``'s callback and still alive: load, not a leak), the
items waiting in every ``SampleQueue`` and every WebSocket client's backlog, threads,
fds. With ``--frames`` > 0 (tracemalloc on), a snapshot is taken ``--base-after`` s
in, and every ``--report-every`` s OUTDIR/growth-<minutes>.txt lists the top growth
since it by traceback, queued payloads left out.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import threading
import time
import tracemalloc
import weakref
from pathlib import Path
from typing import Any


def rss_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return 0


class Watch:
    """Counts what waits in the show's queues (every ``SampleQueue`` and ``WebClient`` made)."""

    def __init__(self) -> None:
        from sonibus.bus import queue, web
        self.queues: weakref.WeakSet[Any] = weakref.WeakSet()
        self.clients: weakref.WeakSet[Any] = weakref.WeakSet()
        for cls, into in ((queue.SampleQueue, self.queues), (web.WebClient, self.clients)):
            init = cls.__init__

            def tracked(obj: Any, *args: Any, _init: Any = init, _into: Any = into, **kwargs: Any) -> None:
                _init(obj, *args, **kwargs)
                _into.add(obj)
            cls.__init__ = tracked  # type: ignore[method-assign]

    def waiting(self) -> dict[str, int]:
        return {"queued": sum(len(q) for q in list(self.queues)),
                "backlog": sum(len(c.backlog) for c in list(self.clients)),
                "queues": len(self.queues), "web_clients": len(self.clients)}


def queued_filters() -> list[tracemalloc.Filter]:
    """Filters that leave out what ``Bus.subscribe``'s callback allocated (a sample's key,
    payload and tuple): alive only while it waits in a queue or is being handled."""
    from sonibus.bus import node
    lines: set[int] = set()
    codes = [node.Bus._kept.__code__, *(c for c in node.Bus.subscribe.__code__.co_consts
                                       if getattr(c, "co_name", "") == "enqueue")]
    for code in codes:
        lines.update(line for _, _, line in code.co_lines() if line is not None)
    return [tracemalloc.Filter(False, node.__file__, line, all_frames=True) for line in sorted(lines)]


def snapshot(leave_out: list[tracemalloc.Filter]) -> tracemalloc.Snapshot:
    return tracemalloc.take_snapshot().filter_traces([
        tracemalloc.Filter(False, tracemalloc.__file__), tracemalloc.Filter(False, "<frozen importlib._bootstrap>"),
        tracemalloc.Filter(False, "<frozen importlib._bootstrap_external>"), *leave_out])


def traced_queued(leave_out: list[tracemalloc.Filter]) -> int:
    """Bytes traced for samples still alive (the complement of ``leave_out``)."""
    snap = tracemalloc.take_snapshot()
    kept = snap.filter_traces(leave_out)
    return sum(t.size for t in snap.traces) - sum(t.size for t in kept.traces)


def watcher(out: Path, args: argparse.Namespace, watch: Watch) -> None:
    started = time.monotonic()
    leave_out = queued_filters() if args.frames else []
    base: tracemalloc.Snapshot | None = None
    next_report = args.base_after + args.report_every
    with (out / "samples.jsonl").open("a") as samples:
        while True:
            time.sleep(args.every)
            now = time.monotonic() - started
            row: dict[str, Any] = {"t": round(now, 1), "rss": rss_bytes(), "threads": threading.active_count(),
                                   "fds": len(os.listdir("/proc/self/fd")), **watch.waiting()}
            if args.frames:
                row["traced"], row["traced_peak"] = tracemalloc.get_traced_memory()
                row["tracemalloc_overhead"] = tracemalloc.get_tracemalloc_memory()
                if args.queued_every and int(now / args.every) % args.queued_every == 0:
                    row["traced_queued"] = traced_queued(leave_out)
                if base is None and now >= args.base_after:
                    gc.collect()
                    base = snapshot(leave_out)
                    row["base"] = True
                elif base is not None and now >= next_report:
                    next_report += args.report_every
                    gc.collect()
                    report(out / f"growth-{now / 60:05.1f}.txt", base, snapshot(leave_out), row)
            samples.write(json.dumps(row) + "\n")
            samples.flush()


def report(path: Path, base: tracemalloc.Snapshot, now: tracemalloc.Snapshot, row: dict[str, Any]) -> None:
    with path.open("w") as f:
        f.write(f"{json.dumps(row)}\n")
        total = sum(s.size_diff for s in now.compare_to(base, "filename"))
        f.write(f"growth since the base, queued payloads left out: {total / 1e6:+.2f} MB\n\n== by line\n")
        for stat in now.compare_to(base, "lineno")[:25]:
            f.write(f"{stat.size_diff / 1e3:+9.1f} kB {stat.count_diff:+7d} blocks  {stat.traceback[0]}\n")
        f.write("\n== by traceback\n")
        for stat in now.compare_to(base, "traceback")[:15]:
            f.write(f"{stat.size_diff / 1e3:+.1f} kB {stat.count_diff:+d} blocks\n")
            for line in stat.traceback.format()[-16:]:
                f.write(f"    {line}\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config")
    parser.add_argument("out", type=Path)
    parser.add_argument("--frames", type=int, default=0, help="tracemalloc frames (0: off)")
    parser.add_argument("--every", type=float, default=10.0, help="seconds between samples")
    parser.add_argument("--queued-every", type=int, default=6, help="measure queued payloads every N samples")
    parser.add_argument("--base-after", type=float, default=300.0, help="seconds before the base snapshot")
    parser.add_argument("--report-every", type=float, default=600.0, help="seconds between growth reports")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.frames:
        tracemalloc.start(args.frames)
    watch = Watch()
    threading.Thread(target=watcher, args=(args.out, args, watch), daemon=True, name="soak-trace").start()
    from sonibus.bus.cli.app import console_main
    sys.argv = ["sonibus", "-v", "run", args.config]
    console_main()  # (as the sonibus script: SIGTERM and Ctrl-C end it cleanly)


if __name__ == "__main__":
    main()
