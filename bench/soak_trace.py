"""``sonibus run CONFIG`` in this process, watched from inside: what ``soak_show.py --trace``
runs instead of ``sonibus run`` to tell Python's growth from native growth, and to
name the lines that allocate what stays.

    .venv/bin/python bench/soak_trace.py CONFIG OUTDIR [--frames 10] [--every 10] [--base-after 300]
        [--report-every 600]

Every ``--every`` s a line of OUTDIR/samples.jsonl: RSS, glibc's bytes in use and
free in its arenas (``mallinfo2``: a leak grows the first, fragmentation the second),
Python's allocated blocks, the items waiting in every ``SampleQueue`` and every
WebSocket client's backlog, threads, fds; every ``--queued-every`` samples after
``--base-after`` s, the growth of Python's objects by type. With ``--frames`` > 0
(tracemalloc on, the show several times slower): its traced memory, the part of it
that is samples waiting in the nodes' queues (payloads allocated by ``Bus.subscribe``'s
callback and still alive: load, not a leak), a snapshot ``--base-after`` s in, and
every ``--report-every`` s OUTDIR/growth-<minutes>.txt with the top growth since it
by line and by traceback, queued payloads left out.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import sys
import threading
import time
import tracemalloc
import weakref
from collections import Counter
from pathlib import Path
from typing import Any


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                     "fsmblks", "uordblks", "fordblks", "keepcost")]


_libc = ctypes.CDLL(None)
_libc.mallinfo2.restype = _MallInfo2


def malloc_bytes() -> dict[str, int]:
    """glibc's view (``mallinfo2``, every arena): bytes in use, free in its arenas (kept, not
    given back: fragmentation), and in blocks of their own (mmap). Python's objects of more
    than 512 bytes, numpy's arrays and Zenoh's Rust side all allocate here."""
    info = _libc.mallinfo2()
    return {"malloc_used": info.uordblks, "malloc_free": info.fordblks, "malloc_mmap": info.hblkhd}


def types_now() -> Counter[str]:
    return Counter(type(o).__qualname__ for o in gc.get_objects())


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


class Queued:
    """Tells the traces of samples still alive (what ``Bus.subscribe``'s callback allocated: a
    sample's key, payload and tuple, alive only while it waits in a queue or is being handled)
    from the rest. On raw traces: ``Snapshot.filter_traces`` takes minutes on a show's."""

    def __init__(self) -> None:
        from sonibus.bus import node
        self.file = node.__file__
        self.lines: set[int] = set()
        codes = [node.Bus._kept.__code__, *(c for c in node.Bus.subscribe.__code__.co_consts
                                           if getattr(c, "co_name", "") == "enqueue")]
        for code in codes:
            self.lines.update(line for _, _, line in code.co_lines() if line is not None)

    def _queued(self, trace: Any) -> bool:
        return any(f == self.file and line in self.lines for f, line in trace[2])

    def split(self, snap: tracemalloc.Snapshot) -> tuple[tracemalloc.Snapshot, int]:
        """The snapshot without queued samples nor tracemalloc's and the importer's own
        allocations, and the bytes of queued samples."""
        kept, queued = [], 0
        for trace in snap.traces._traces:  # (domain, size, ((file, line), ...), frames)
            if self._queued(trace):
                queued += trace[1]
            elif trace[2] and not trace[2][0][0].startswith(("<frozen importlib", tracemalloc.__file__)):
                kept.append(trace)
        return tracemalloc.Snapshot(kept, snap.traceback_limit), queued


def watcher(out: Path, args: argparse.Namespace, watch: Watch) -> None:
    started = time.monotonic()
    queued = Queued() if args.frames else None
    base: tracemalloc.Snapshot | None = None
    types_base: Counter[str] | None = None
    next_report = args.base_after + args.report_every
    with (out / "samples.jsonl").open("a") as samples:
        while True:
            time.sleep(args.every)
            now = time.monotonic() - started
            row: dict[str, Any] = {"t": round(now, 1), "rss": rss_bytes(), "threads": threading.active_count(),
                                   "fds": len(os.listdir("/proc/self/fd")), **watch.waiting(), **malloc_bytes(),
                                   "py_blocks": sys.getallocatedblocks()}
            if int(now / args.every) % args.queued_every == 0:  # Python's objects by type: what grows
                counts = types_now()
                types_base = types_base if types_base is not None or now < args.base_after else counts
                if types_base is not None:
                    row["types_growth"] = dict((counts - types_base).most_common(12))
            if args.frames:
                row["traced"], row["traced_peak"] = tracemalloc.get_traced_memory()
                row["tracemalloc_overhead"] = tracemalloc.get_tracemalloc_memory()
                due = (base is None and now >= args.base_after) or (base is not None and now >= next_report)
                if due or int(now / args.every) % args.queued_every == 0:
                    if due:
                        gc.collect()
                    snap, row["traced_queued"] = queued.split(tracemalloc.take_snapshot())
                    row["traced_kept"] = sum(t[1] for t in snap.traces._traces)
                    if base is None and due:
                        base, row["base"] = snap, True
                    elif due:
                        next_report += args.report_every
                        report(out / f"growth-{now / 60:05.1f}.txt", base, snap, row)
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
    parser.add_argument("--queued-every", type=int, default=30, help="snapshot (queued payloads) every N samples")
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
