"""The show soak: one ``sonibus run`` holding every built-in node of an installation,
clients coming and going, for minutes (a quick check) or hours (the long form), and
whether its memory stays flat.

    .venv/bin/python bench/soak_show.py                      # the short form: 6 minutes
    .venv/bin/python bench/soak_show.py --minutes 70 --name soak_show_long
    .venv/bin/python bench/soak_show.py --minutes 30 --trace 10   # under tracemalloc (soak_trace.py)

The show (``show_toml``): a simulated Pepper at 50 frames/s, the ``show`` program when
it is installed (idle gestures, a scenario from the kiosk and from OSC; otherwise the
simulator's own autoplay), an OSC sink with a plain and a bundle target, the OSC
gateway, features, a recorder rotating its file every ``--rotate-s`` (old files deleted
as an operator would), MIDI on a private JACK server (dummy driver), the web pages
with a kiosk, OSCQuery and Foxglove. Clients (``soak_clients.py``) attach for
``--cycle-s`` then leave for ``--away-s``, again and again, until ``--leave-at`` of
the run; then nothing but the show runs, to tell a cost of clients from a creep.

Every ``--every`` s the run's RSS, open files and threads are read from /proc. The
slope is a least-squares fit of RSS over the steady part, after ``--warmup-min``
(default: a fifth of the run, at least 1 and at most 15 minutes: imports done on first
use, the queues' and allocators' working set, the first client cycles and the first
rotation, measured in docs/performance.md, "Days of uptime"); also per phase
(clients attached, after they left). Restarts: a worker restarted by its node (the
log's "restarting it"), and the run itself ending before the soak did (0 expected).

Writes bench/results/<name>.json (default ``soak_show``): the figures, a summary for
``make bench``'s table, and the samples.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import numpy as np
from common import write
from soak_clients import Clients, Endpoints

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the tests package: its process helpers

from tests.fuzz.show import SONIBUS, Child, _has_port, _jack_up, until

HERE = Path(__file__).resolve().parent
GOAL_MB_H = 2.0
LONG_MIN = 60.0  # the goal is judged on a run at least this long
MAPPINGS_EVERY_S = 300.0
PARTIAL_EVERY_S = 300.0  # the results so far are written this often (marked partial)


@dataclass
class Ports:
    bus: int = field(default_factory=lambda: free_port())
    web: int = field(default_factory=lambda: free_port())
    oscquery: int = field(default_factory=lambda: free_port())
    foxglove: int = field(default_factory=lambda: free_port())
    gateway: int = field(default_factory=lambda: free_port(socket.SOCK_DGRAM))
    plain: int = field(default_factory=lambda: free_port(socket.SOCK_DGRAM))
    bundle: int = field(default_factory=lambda: free_port(socket.SOCK_DGRAM))


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def has_show() -> bool:
    """Whether the ``show`` program is installed (it lands beside this benchmark)."""
    return "show" in {e.name for e in entry_points(group="sonibus.adapters")}


def show_toml(ports: Ports, recordings: Path, rotate_s: float, show: bool) -> str:
    """The installation: every built-in node in one file, on a private bus."""
    if show:
        robot = 'idle = false'
        program = """
[nodes.show]
adapter = "show"
robot = "pepper"

[nodes.show.idle]
behaviors = ["animations/Stand/Gestures/Hey_1", "animations/Stand/Gestures/Yes_1"]
rest_s = 10
max_per_hour = 360

[nodes.show.scenarios.hello]
steps = [{say = "Hello!"}, {behavior = "animations/Stand/Gestures/Hey_1"}]
"""
        button = 'scenario = "hello"'
    else:
        robot, program, button = "idle = true\nautoplay_s = 20", "", 'behavior = "animations/Stand/Gestures/Hey_1"'
    return f"""\
[bus]
multicast = false
listen = ["tcp/127.0.0.1:{ports.bus}"]

[nodes.pepper]
adapter = "sim"
robot = "pepper"
rate_hz = 50
{robot}
{program}
[nodes.sound]
adapter = "osc"
subscribe = ["pepper/joints/*", "pepper/events/*", "pepper/derived/**"]
targets = ["127.0.0.1:{ports.plain}", {{to = "127.0.0.1:{ports.bundle}", bundle = true}}]

[nodes.gateway]
adapter = "osc-gateway"
listen = "127.0.0.1:{ports.gateway}"

[nodes.features]
adapter = "features"
robots = "pepper"

[nodes.logger]
adapter = "recorder"
path = "{recordings}/show-{{time}}.mcap"
rotate_s = {rotate_s:g}
status_every_s = 600

[nodes.midi]
adapter = "midi"
api = "jack"
map = [{{key = "pepper/joints/HeadPitch", pitchbend = true, channel = 2}}]

[nodes.web]
adapter = "web"
listen = "127.0.0.1:{ports.web}"

[nodes.web.kiosk]
robot = "pepper"

[[nodes.web.kiosk.buttons]]
id = "hey"
label = "Hey"
{button}

[nodes.oscquery]
adapter = "oscquery"
listen = "127.0.0.1:{ports.oscquery}"
gateway = "127.0.0.1:{ports.gateway}"
mdns = false

[nodes.foxglove]
adapter = "foxglove"
listen = "127.0.0.1:{ports.foxglove}"

[nodes.console]
adapter = "console"
every_s = 10
"""


def mappings(pid: int) -> dict[str, float]:
    """The process's resident MB by kind of mapping (/proc/PID/smaps): ``heap`` (glibc's main
    arena), ``arenas`` (anonymous mappings aligned on 64 MiB: glibc's other arenas, where
    threads' mallocs go, Zenoh's Rust side's too), ``anon`` (other anonymous ones: Python's
    small-object arenas, large blocks, thread stacks), ``files``."""
    kinds: dict[str, float] = {}
    kind = "files"
    with contextlib.suppress(OSError), open(f"/proc/{pid}/smaps") as smaps:
        for line in smaps:
            if line[0] in "0123456789abcdef" and "-" in line.split(" ", 1)[0]:
                span, *rest = line.split()
                low = int(span.split("-")[0], 16)
                name = rest[4] if len(rest) > 4 else ""
                kind = ("heap" if name == "[heap]" else "files" if name.startswith("/") else "other" if name
                        else "arenas" if low % (64 << 20) == 0 else "anon")
            elif line.startswith("Rss:"):
                kinds[kind] = kinds.get(kind, 0.0) + int(line.split()[1]) / 1024
    return {k: round(v, 1) for k, v in sorted(kinds.items())}


class Process:
    """The run's RSS, open files and threads, read from /proc every ``every_s``; its
    mappings (``mappings``) every ``MAPPINGS_EVERY_S``."""

    def __init__(self, pid: int, every_s: float) -> None:
        self.pid, self.started = pid, time.monotonic()
        self.samples: list[tuple[float, float, int, int]] = []  # (s since start, RSS MB, fds, threads)
        self.mappings: list[tuple[float, dict[str, float]]] = []
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(every_s,), daemon=True)
        self._thread.start()

    def read(self) -> tuple[float, int, int] | None:
        try:
            status = Path(f"/proc/{self.pid}/status").read_text()
            fds = len(os.listdir(f"/proc/{self.pid}/fd"))
        except OSError:
            return None
        fields = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
        return int(fields["VmRSS"].split()[0]) / 1024, fds, int(fields["Threads"])

    def _run(self, every_s: float) -> None:
        next_mappings = 0.0
        while not self._done.wait(every_s):
            now, since = self.read(), time.monotonic() - self.started
            if now is not None:
                self.samples.append((since, *now))
            if since >= next_mappings:
                next_mappings += MAPPINGS_EVERY_S
                self.mappings.append((round(since / 60, 1), mappings(self.pid)))

    def close(self) -> None:
        self._done.set()
        self._thread.join(5.0)


def fit(samples: list[tuple[float, float, int, int]], start_s: float, end_s: float) -> dict[str, Any]:
    """RSS slope (MB/h, least squares) over ``[start_s, end_s)``, its standard error, and the
    range of RSS, fds and threads there."""
    part = [s for s in samples if start_s <= s[0] < end_s]
    if len(part) < 3:
        return {"from_min": start_s / 60, "to_min": end_s / 60, "samples": len(part)}
    t = np.array([s[0] for s in part]) / 3600
    rss = np.array([s[1] for s in part])
    slope, intercept = np.polyfit(t, rss, 1)
    residuals = rss - (slope * t + intercept)
    stderr = math.sqrt(float(residuals @ residuals) / (len(t) - 2) / float(((t - t.mean()) ** 2).sum()))
    return {"from_min": round(start_s / 60, 2), "to_min": round(part[-1][0] / 60, 2), "samples": len(part),
            "slope_mb_h": round(float(slope), 2), "slope_stderr_mb_h": round(stderr, 2),
            "rss_mb": [round(float(rss.min()), 1), round(float(rss.max()), 1)],
            "rss_first_last_mb": [round(float(rss[0]), 1), round(float(rss[-1]), 1)],
            "fds": [min(s[2] for s in part), max(s[2] for s in part)],
            "threads": [min(s[3] for s in part), max(s[3] for s in part)]}


class Soak:
    """The show, its JACK server and its clients; ``close()`` ends all of it."""

    def __init__(self, args: argparse.Namespace, tmp: Path) -> None:
        self.args, self.tmp = args, tmp
        self.ports = Ports()
        self.recordings = tmp / "recordings"
        self.recordings.mkdir()
        self.show = has_show()
        self.jack_name = f"soak-{os.getpid()}"
        self.children: list[Child] = []
        self.run: Child | None = None
        self.ended_at: float | None = None  # minutes into the soak when the run ended on its own
        self.stop_s = math.nan               # how long the run took to end after SIGTERM

    def start(self) -> None:
        os.environ["JACK_DEFAULT_SERVER"] = self.jack_name
        os.environ["JACK_NO_START_SERVER"] = "1"
        jackd = self._child(["jackd", "--no-realtime", "-n", self.jack_name, "-d", "dummy", "-r", "48000",
                             "-p", "256"])
        until(lambda: not jackd.alive or _jack_up(), 10, f"jackd -n {self.jack_name}", 0.1)
        config = self.tmp / "show.toml"
        config.write_text(show_toml(self.ports, self.recordings, self.args.rotate_s, self.show))
        if self.args.trace is None:
            command = [SONIBUS, "-v", "run", str(config)]
        else:
            command = [sys.executable, str(HERE / "soak_trace.py"), str(config), str(self.tmp / "trace"),
                       "--frames", str(self.args.trace), "--base-after", str(self.args.warmup_min * 60),
                       "--report-every", str(self.args.trace_report_s)]
        self.run = run = self._child(command)
        until(lambda: not run.alive or any("sonibus: running" in text for _, text in run.out), 300,
              "sonibus run to start every node", 0.1)
        if not run.alive:
            raise RuntimeError(f"sonibus run ended at start: {run.tail(30)}")
        until(lambda: _has_port("midi:"), 10, "the midi node's JACK port", 0.1)

    def endpoints(self) -> Endpoints:
        p = self.ports
        return Endpoints(web=p.web, oscquery=p.oscquery, foxglove=p.foxglove, gateway=p.gateway,
                         osc_targets=(p.plain, p.bundle), scenario="hello" if self.show else "", midi_port="midi:")

    def tidy(self) -> None:
        """Delete finished recordings but the newest two, as an operator's cron would."""
        files = sorted(self.recordings.glob("show-*.mcap"))
        for old in files[:-2]:
            old.unlink(missing_ok=True)

    def _child(self, args: list[str]) -> Child:
        child = Child(args, env=dict(os.environ))
        self.children.append(child)
        return child

    def close(self) -> int | None:
        """End everything; the run's exit code (130 after its SIGTERM, as under systemd; None: killed)."""
        started = time.monotonic()
        code = self.run.stop(signal.SIGTERM, 15.0) if self.run is not None else None
        self.stop_s = time.monotonic() - started
        if self.run is not None:
            (self.tmp / "run.log").write_text("\n".join(t for _, t in self.run.err) + "\n")
        for child in reversed(self.children):
            if child is not self.run:
                child.stop(signal.SIGINT, 5.0)
        for leftover in Path("/dev/shm").glob(f"jack_sem.*_{self.jack_name}_*"):
            leftover.unlink(missing_ok=True)
        return code


def soak(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    show = Soak(args, tmp)
    try:
        show.start()
        assert show.run is not None
        process = Process(show.run.pid, args.every)
        clients = Clients(show.endpoints())
        end, leave = args.minutes * 60, args.leave_at * args.minutes * 60
        print(f"soak: {args.minutes:g} min, clients until {leave / 60:.1f} min, warm-up {args.warmup_min:g} min; "
              f"log and recordings in {tmp}", flush=True)
        next_partial = time.monotonic() + PARTIAL_EVERY_S
        while (now := time.monotonic() - process.started) < end and show.run.alive:
            if now < leave:
                clients.cycle(min(args.cycle_s, leave - now))
                show.tidy()
                pause = min(args.away_s, max(0.0, end - (time.monotonic() - process.started)))
            else:
                show.tidy()
                pause = min(60.0, end - now)
            if pause > 0:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    show.run.popen.wait(pause)  # (returns early if the run ends)
            if time.monotonic() >= next_partial:  # what it found so far, should the soak be cut short
                next_partial += PARTIAL_EVERY_S
                log_now = "\n".join(text for _, text in show.run.err)
                write(args.name, {**analyse(args, show, process, clients, None, log_now), "partial": True})
            last = process.samples[-1] if process.samples else None
            if last:
                print(f"  {last[0] / 60:5.1f} min: rss {last[1]:.1f} MB, fds {last[2]}, threads {last[3]}, "
                      f"cycles {clients.counts['cycles']}, client errors {clients.counts['client_errors']}",
                      flush=True)
        if not show.run.alive:
            show.ended_at = (time.monotonic() - process.started) / 60
        process.close()
    finally:
        code = show.close()
    log = (tmp / "run.log").read_text() if (tmp / "run.log").exists() else ""
    return analyse(args, show, process, clients, code, log)


def analyse(args: argparse.Namespace, show: Soak, process: Process, clients: Clients, code: int | None,
            log: str) -> dict[str, Any]:
    samples, warm = process.samples, args.warmup_min * 60
    leave, end = args.leave_at * args.minutes * 60, samples[-1][0] + 1 if samples else 0
    steady = fit(samples, warm, end)
    phases = {"clients_attached": fit(samples, warm, leave),
              "clients_left": fit(samples, leave + args.settle_s, end)}
    worker_restarts = sum("restarting it in" in line for line in log.splitlines())
    failures = [line for line in log.splitlines() if ": error" in line.lower() or "Traceback" in line][:10]
    minutes = samples[-1][0] / 60 if samples else 0.0
    slope = steady.get("slope_mb_h")
    long_form = minutes >= LONG_MIN
    met = "yes" if slope is not None and slope <= GOAL_MB_H else "no"
    restarts = worker_restarts + (1 if show.ended_at is not None else 0)
    result: dict[str, Any] = {
        "machine": f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f} at the end",
        "minutes": round(minutes, 1), "warmup_min": args.warmup_min, "show_program": show.show,
        "traced": args.trace is not None, "cycle_s": args.cycle_s, "away_s": args.away_s,
        "steady": steady, "phases": phases,
        "rss_start_mb": samples[0][1] if samples else None,
        "restarts": {"workers": worker_restarts, "run_ended_at_min": show.ended_at},
        "exit_code": code, "stop_s": round(show.stop_s, 2), "errors_in_log": failures,
        "clients": dict(clients.counts), "client_errors": clients.errors,
        "mappings_mb": process.mappings,
        "samples": [[round(t, 1), rss, fds, threads] for t, rss, fds, threads in samples],
    }
    fds, threads = steady.get("fds", ["?", "?"]), steady.get("threads", ["?", "?"])
    first, last = samples[0] if samples else (0, 0, 0, 0), samples[-1] if samples else (0, 0, 0, 0)
    clean = restarts == 0 and code == 130 and show.stop_s <= 3 and last[2] <= first[2] + 2 and last[3] <= first[3]
    form = "long form" if long_form else "short form"
    result["summary"] = [
        {"scenario": f"show soak ({form}): {minutes:.0f} min, every node, {clients.counts['cycles']} client cycles, "
                     f"RSS slope after {args.warmup_min:g} min", "sonibus": f"{slope} ± "
                     f"{steady.get('slope_stderr_mb_h')} MB/h", "baseline": f"{result['rss_start_mb']} MB at start",
         "goal": f"≤ {GOAL_MB_H:g} MB/h over ≥ {LONG_MIN:g} min" if long_form else "(judged on the long form)",
         "met": met if long_form else ""},
        {"scenario": f"show soak ({form}): RSS slope, clients attached / after they left",
         "sonibus": " / ".join(f"{p.get('slope_mb_h')} MB/h" for p in phases.values()), "goal": "", "met": ""},
        {"scenario": f"show soak ({form}): fds, threads at the start → at the end (min–max), restarts, exit",
         "sonibus": f"fds {first[2]} → {last[2]} ({fds[0]}–{fds[1]}), threads {first[3]} → {last[3]} "
                    f"({threads[0]}–{threads[1]}), restarts {restarts}, exit {code} in {show.stop_s:.1f} s",
         "goal": "as many at the end, 0 restarts, SIGTERM: exit 130 within 3 s", "met": "yes" if clean else "no"},
    ]
    return result


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=6.0, help="how long (default 6; the long form: 60 or more)")
    parser.add_argument("--warmup-min", type=float, help="minutes left out of the fit (default: a fifth, 1 to 15)")
    parser.add_argument("--leave-at", type=float, default=0.6, help="clients stop coming at this part of the run")
    parser.add_argument("--cycle-s", type=float, default=60.0, help="seconds clients stay attached each cycle")
    parser.add_argument("--away-s", type=float, default=15.0, help="seconds between cycles")
    parser.add_argument("--settle-s", type=float, default=60.0, help="after the clients left, left out of that fit")
    parser.add_argument("--rotate-s", type=float, default=60.0, help="the recorder's rotation")
    parser.add_argument("--every", type=float, default=2.0, help="seconds between samples")
    parser.add_argument("--trace", type=int, help="run under tracemalloc with this many frames (soak_trace.py)")
    parser.add_argument("--trace-report-s", type=float, default=600.0, help="seconds between growth reports")
    parser.add_argument("--name", default="soak_show", help="results name (default soak_show)")
    parser.add_argument("--keep", action="store_true", help="keep the log, recordings and trace")
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, _interrupt)  # (ends the show and its JACK server, as Ctrl-C does)
    if args.warmup_min is None:
        args.warmup_min = min(15.0, max(1.0, args.minutes / 5))
    tmp = Path(tempfile.mkdtemp(prefix="soak-show-"))
    result = soak(args, tmp)
    print(f"results in {write(args.name, result)}")
    for row in result["summary"]:
        print(f"  {row['scenario']}: {row['sonibus']} {row['met']}")
    ok = result["exit_code"] == 130 and not result["restarts"]["workers"] and result["restarts"]["run_ended_at_min"] \
        is None
    if args.keep or not ok or args.trace is not None:
        print(f"kept in {tmp}")
    else:
        shutil.rmtree(tmp, ignore_errors=True)
    if not ok:
        sys.exit(f"the show did not run through: exit {result['exit_code']}, restarts {result['restarts']}")


if __name__ == "__main__":
    main()
