"""Maximum lossless joint samples/s through one OSC sink process, beside raw UDP
sent straight from one Python process at the same rates (issue 9, scenario b).

sonibus path, per step of the ramp: publisher process(es) put frames of 17
joints per robot as a robot owner does (``botN/frame`` whole, then
``botN/joints/JK`` each, msgpack, ``Bus.stream_publisher``); the OSC sink is its own
process (``sonibus run``, ``max_age_ms = 0`` so nothing is dropped as stale,
listening on loopback TCP, the publishers connect to it); a receiver process
counts the datagrams (8 MB socket buffer, gc off). ``--bundles``: the sink
sends a bundle per frame and the baseline the same bundles. Each step gets a fresh sink
and publishers, so the sink's own counters (``received``, ``sent``,
``queue_dropped``) are per step. Baseline, same run, interleaved: one process
sends the same OSC datagrams (built beforehand) with ``sendto`` to the same
receiver at the same rate and batches.

Per step: offered (target) and achieved (what the publishers managed to put)
rates, delivered at the receiver, loss, lag (last datagram after the
publishers ended), and CPU % (of one core) of the sink, the publishers and the
receiver. The result is the highest step with zero loss.

    .venv/bin/python bench/sink_throughput.py [--rates 5000 10000 20000 40000 80000 120000]
        [--seconds 3] [--robots 4] [--publishers 1]

Writes bench/results/sink_throughput.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import multiprocessing
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from common import free_port, write

SONIBUS = str(Path(sys.executable).with_name("sonibus"))
JOINTS = 17
TICK = os.sysconf("SC_CLK_TCK")
SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux: may exceed rmem_max (needs CAP_NET_ADMIN)
CONTEXT = multiprocessing.get_context("spawn")  # children never inherit a Zenoh runtime


# -- helpers shared with recorder_rate.py and midi_rate.py -----------------------------


def cpu_times(pid: int) -> tuple[float, float]:
    """User and system CPU seconds of process ``pid`` (all its threads), from /proc/<pid>/stat."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rpartition(")")[2].split()
    return int(fields[11]) / TICK, int(fields[12]) / TICK  # utime, stime (fields 14, 15 of proc(5))


def cpu_seconds(pid: int) -> float:
    return sum(cpu_times(pid))


def thread_cpu(pid: int) -> dict[str, float]:
    """CPU seconds of the threads of ``pid`` summed by thread name (Zenoh's runtime names its
    threads; Python threads keep the process's name)."""
    out: dict[str, float] = {}
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{task}/stat") as f:
                head, _, tail = f.read().rpartition(")")
        except FileNotFoundError:  # a thread that just ended
            continue
        name = re.sub(r"[-_:]?\d+$", "", head.partition("(")[2]) or "?"
        fields = tail.split()
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / TICK
    return out


def thread_share(before: dict[str, float], after: dict[str, float], seconds: float) -> dict[str, float]:
    """CPU % of one core per thread name between two ``thread_cpu`` readings, largest first."""
    share = {k: 100.0 * (v - before.get(k, 0.0)) / seconds for k, v in after.items()}
    return dict(sorted(((k, round(v, 1)) for k, v in share.items() if v >= 0.5), key=lambda kv: -kv[1]))


def stop_process(popen: subprocess.Popen, timeout: float = 10.0) -> None:
    """SIGTERM (``sonibus`` and jackd stop cleanly on it; SIGINT may be ignored, inherited from a
    shell's background job), then SIGKILL of its process group if it is not gone within
    ``timeout`` — also when this wait is itself interrupted."""
    try:
        if popen.poll() is None:
            popen.send_signal(signal.SIGTERM)
        popen.wait(timeout)
    except subprocess.TimeoutExpired:
        pass
    finally:
        if popen.poll() is None:
            os.killpg(popen.pid, signal.SIGKILL)
            popen.wait(5)


def stop_children(children: list[Any]) -> None:
    """Terminate multiprocessing children still alive (after their own clean exit had its chance)."""
    for child in children:
        child.join(5)
        if child.is_alive():
            child.kill()
            child.join(5)


def publish(endpoint: str, robots: list[int], frames_per_s: float, seconds: float, ready: Any, go: Any,
            finish: Any, out: Any, value: str = "sine", info: bool = False, per_joint_keys: bool = False) -> None:
    """Put one frame of 17 joints of each of ``robots`` every 1/``frames_per_s`` s, ``seconds``
    long, once ``go`` is set, as a robot owner does (the frame whole, then each joint); report
    how many joint samples were put, how long it took and the CPU used, then stay connected
    until ``finish`` (so the sink drains before anything leaves). Waits for a subscriber of
    the frames (of the joint keys if ``per_joint_keys``).

    ``value``: ``sine`` (a wave per joint) or ``ramp`` (changes every frame by 1/127 of the
    range, so a 7-bit MIDI controller changes with every sample). ``info``: serve ``botN/info``
    (joints J0..J16 in 0..1) and put a few warm-up frames first, so a sink that needs the
    ranges has them before the measured frames."""
    gc.disable()
    from sonibus import schemas
    from sonibus.bus import Bus, BusConfig, codec, framing, open_session

    session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    try:
        bus = Bus(session, node=f"bench-publisher-{robots[0]}")
        names = [f"J{j}" for j in range(JOINTS)]
        streams = [[bus.stream_publisher(f"bot{r}/joints/{n}") for n in names] for r in robots]
        frames_out = [bus.stream_publisher(f"bot{r}/frame") for r in robots]
        watched = [p for row in streams for p in row] if per_joint_keys else frames_out
        queryables = []  # kept referenced for the life of the session
        for r in robots if info else ():
            description = codec.encode({  # a whole robot info (the sinks' gate checks it by its schema)
                "robot": f"bot{r}", "model": "bench", "rate_hz": frames_per_s, "behaviors": [], "postures": [],
                "adapter": "bench", "schema_version": schemas.VERSION,
                "owner": {"host": bus.host, "node": bus.node},
                "joints": [{"name": f"J{j}", "unit": "rad", "min": 0.0, "max": 1.0, "max_velocity": 1.0}
                           for j in range(JOINTS)]})
            queryables.append(bus.serve(f"bot{r}/info", lambda q, d=description: q.reply(
                q.key_expr, d, encoding=codec.ENCODING)))
        deadline = time.monotonic() + 30.0
        while not all(p.matching_status.matching for p in watched):
            if time.monotonic() > deadline:
                out.put({"error": f"no subscriber matched bot{robots[0]}'s frames or joints within 30 s"})
                return
            time.sleep(0.02)

        def value_of(frame: int, j: int) -> float:
            return (frame + j) % 128 / 127.0 if value == "ramp" else 0.5 * ((frame * 0.01 + j) % 2.0) - 0.5

        def put_frame(frame: int, t: float) -> int:
            for row, whole in zip(streams, frames_out, strict=True):
                values = [value_of(frame, j) for j in range(JOINTS)]
                whole.put(encode(framing.frame(t, frame, names, values)))
                for publisher, v in zip(row, values, strict=True):
                    publisher.put(encode({"t": t, "seq": frame, "v": v}))
            return JOINTS * len(streams)

        encode = codec.encode
        warm_up = 5 if info else 0  # frames 0..4: the sink asks for the info on its first sample
        for frame in range(warm_up):
            put_frame(frame, time.time())
            time.sleep(0.1)
        ready.set()
        deadline = time.monotonic() + 60.0
        while not go.wait(0.1):
            if finish.is_set() or time.monotonic() > deadline:  # the benchmark gave up
                return
        frames = round(seconds * frames_per_s)
        period = 1.0 / frames_per_s
        cpu0, start = time.process_time(), time.monotonic()
        sent = frame = 0
        while frame < frames and time.monotonic() - start < 2.0 * seconds:
            sent += put_frame(warm_up + frame, time.time())
            frame += 1
            wait = start + frame * period - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        ended = time.monotonic()
        out.put({"sent": sent, "seconds": ended - start, "ended": ended,
                 "cpu_percent": 100.0 * (time.process_time() - cpu0) / (ended - start)})
        finish.wait(60)
    finally:
        session.close()


class Publishers:
    """``count`` publisher processes sharing ``robots`` robots, started together."""

    def __init__(self, endpoint: str, count: int, robots: int, rate: float, seconds: float,
                 value: str = "sine", info: bool = False, per_joint_keys: bool = False) -> None:
        self.go, self.finish, self.out = CONTEXT.Event(), CONTEXT.Event(), CONTEXT.Queue()
        self.ready = [CONTEXT.Event() for _ in range(count)]
        frames_per_s = rate / (robots * JOINTS)
        shares = [list(range(robots))[i::count] for i in range(count)]
        self.processes = [CONTEXT.Process(target=publish, args=(endpoint, share, frames_per_s, seconds, ready,
                                                                 self.go, self.finish, self.out, value, info,
                                                                 per_joint_keys),
                                          daemon=True)
                          for share, ready in zip(shares, self.ready, strict=True)]
        for process in self.processes:
            process.start()

    def wait_ready(self, server: subprocess.Popen, timeout: float = 40.0) -> None:
        """Until every publisher has a matching subscriber; ``server`` (what they connect to) must live."""
        deadline = time.monotonic() + timeout
        for ready, process in zip(self.ready, self.processes, strict=True):
            while not ready.wait(0.1):
                if server.poll() is not None:
                    raise RuntimeError(f"{' '.join(map(str, server.args))} ended with {server.returncode}")
                if not process.is_alive() or not self.out.empty() or time.monotonic() > deadline:
                    error = self.out.get(timeout=1) if not self.out.empty() else {"error": "publisher not ready"}
                    raise RuntimeError(error.get("error", error))

    def run(self, timeout: float) -> dict[str, float]:
        """Start them; wait for every report; the totals."""
        self.go.set()
        reports = [self.out.get(timeout=timeout) for _ in self.processes]
        errors = [r["error"] for r in reports if "error" in r]
        if errors:
            raise RuntimeError(errors[0])
        sent = sum(r["sent"] for r in reports)
        seconds = max(r["seconds"] for r in reports)
        return {"sent": sent, "seconds": seconds, "achieved_per_s": sent / seconds,
                "ended": max(r["ended"] for r in reports),
                "cpu_percent": sum(r["cpu_percent"] for r in reports)}

    def close(self) -> None:
        self.finish.set()
        stop_children(self.processes)


# -- the receiver ---------------------------------------------------------------------


def receive(port: int, ready: Any) -> None:
    """Count datagrams; a datagram starting with NUL is a control message: ``\\0?`` is
    answered with (count, monotonic time of the last counted datagram), ``\\0q`` ends."""
    gc.disable()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, 8 << 20)
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", port))
    ready.set()
    count, last = 0, 0.0
    buffer = bytearray(2048)
    while True:
        n, sender = sock.recvfrom_into(buffer)
        if n and buffer[0] == 0:
            if buffer[1:2] == b"q":
                break
            sock.sendto(struct.pack("<qd", count, last), sender)
            continue
        count += 1
        last = time.monotonic()
    sock.close()


class Receiver:
    """A counting process (``target(port, ready)``, by default ``receive``) and its control socket."""

    def __init__(self, target: Any = receive) -> None:
        self.port = free_port(socket.SOCK_DGRAM)
        ready = CONTEXT.Event()
        self.process = CONTEXT.Process(target=target, args=(self.port, ready), daemon=True)
        self.process.start()
        while not ready.wait(0.1):
            if not self.process.is_alive():
                raise RuntimeError("the receiver did not start")
        self.control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.control.settimeout(5.0)

    def count(self) -> tuple[int, float]:
        self.control.sendto(b"\0?", ("127.0.0.1", self.port))
        return struct.unpack("<qd", self.control.recv(64))

    def drops(self) -> int:
        """The kernel's drop counter of the receiving socket (/proc/net/udp)."""
        local = f"0100007F:{self.port:04X}"
        with open("/proc/net/udp") as f:
            for line in f:
                parts = line.split()
                if parts[1] == local:
                    return int(parts[-1])
        return -1

    def settle(self, expected: int, since: float, quiet_s: float = 0.5, limit_s: float = 10.0) -> tuple[int, float]:
        """Wait until ``expected`` datagrams have come after the first ``since`` counted, or none
        came for ``quiet_s``; (count, time of the last one)."""
        deadline = time.monotonic() + limit_s
        count, last = self.count()
        while count - since < expected and time.monotonic() < deadline:
            time.sleep(0.1)
            count, last = self.count()
            if time.monotonic() - last >= quiet_s:
                break
        return count, last

    def close(self) -> None:
        try:
            self.control.sendto(b"\0q", ("127.0.0.1", self.port))
        finally:
            self.control.close()
            stop_children([self.process])


# -- one step -------------------------------------------------------------------------


STATS = re.compile(r"stopping; (.*)")


def sink_stats(log: str) -> dict[str, int]:
    """The sink's counters from its last log line (``received 1, sent 1, dropped 0, ...``);
    ``queue_dropped``: its queue's drops (``dropped``)."""
    found = STATS.findall(log)
    if not found:
        return {}
    stats = {k: int(v) for k, v in (item.rsplit(" ", 1) for item in found[-1].split(", "))}
    return {**stats, "queue_dropped": stats["dropped"]}


def step_sonibus(receiver: Receiver, rate: float, seconds: float, robots: int, publishers: int,
                 folder: Path, bundles: bool = False) -> dict[str, Any]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = folder / "sink.toml"
    config.write_text(f'[bus]\nmulticast = false\n\n[nodes.sound]\nadapter = "osc"\nsubscribe = "*/joints/*"\n'
                      f'targets = ["127.0.0.1:{receiver.port}"]\nmax_age_ms = 0\nbundle = {str(bundles).lower()}\n')
    log_path = folder / f"sink-{rate:g}.log"
    with open(log_path, "w") as log:
        sink = subprocess.Popen([SONIBUS, "-v", "run", str(config), "--no-multicast", "--listen", endpoint],
                                stdout=subprocess.DEVNULL, stderr=log, start_new_session=True)
    group = None
    try:
        group = Publishers(endpoint, publishers, robots, rate, seconds)
        group.wait_ready(sink)
        count0, _ = receiver.count()
        drops0, sink_cpu0, receiver_cpu0 = receiver.drops(), cpu_times(sink.pid), cpu_seconds(receiver.process.pid)
        threads0 = thread_cpu(sink.pid)
        started = time.monotonic()
        pub = group.run(timeout=3 * seconds + 30)
        sink_user, sink_sys = (b - a for a, b in zip(sink_cpu0, cpu_times(sink.pid), strict=True))
        sink_cpu, receiver_cpu = sink_user + sink_sys, cpu_seconds(receiver.process.pid) - receiver_cpu0
        window = time.monotonic() - started
        threads = thread_share(threads0, thread_cpu(sink.pid), window)
        count, last = receiver.settle(pub["sent"] // _per(bundles), count0)
        drops = receiver.drops() - drops0
    finally:
        if group is not None:
            group.close()
        stop_process(sink)
    stats = sink_stats(log_path.read_text())
    delivered = (count - count0) * _per(bundles)
    return {"offered_per_s": rate, "sent": pub["sent"], "achieved_per_s": pub["achieved_per_s"],
            "publisher_cpu_percent": pub["cpu_percent"], "delivered": delivered,
            "delivered_per_s": delivered / pub["seconds"], "lost": pub["sent"] - delivered,
            "loss_percent": 100.0 * (pub["sent"] - delivered) / max(1, pub["sent"]),
            "lag_s": max(0.0, last - pub["ended"]) if delivered else None,
            "sink_cpu_percent": 100.0 * sink_cpu / window, "sink_system_cpu_percent": 100.0 * sink_sys / window,
            "sink_threads_cpu_percent": threads,
            "receiver_cpu_percent": 100.0 * receiver_cpu / window,
            "receiver_socket_drops": drops, "sink": stats}


def _per(bundles: bool) -> int:
    """Joint samples per datagram."""
    return JOINTS if bundles else 1


def send_raw(port: int, robots: int, rate: float, seconds: float, ready: Any, go: Any, out: Any,
             bundles: bool = False) -> None:
    """The baseline: the sink's datagrams (a message per joint, or a bundle per frame), built
    beforehand, sent with sendto in the same batches (``rate`` 0: unpaced, as fast as it goes)."""
    gc.disable()
    from sonibus.adapters.osc.encode import bundle, floats, timetag
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 << 20)
    batch = [floats(f"/bot{r}/joints/J{j}", (0.25,)) for r in range(robots) for j in range(JOINTS)]
    if bundles:
        batch = [bundle(timetag(time.time()), batch[r * JOINTS:(r + 1) * JOINTS]) for r in range(robots)]
    destination = ("127.0.0.1", port)
    period = len(batch) * _per(bundles) / rate if rate else 0.0
    frames = round(seconds / period) if rate else sys.maxsize
    ready.set()
    go.wait(30)
    cpu0, start = time.process_time(), time.monotonic()
    sent = frame = 0
    while frame < frames and time.monotonic() - start < (2.0 if rate else 1.0) * seconds:
        for datagram in batch:
            sock.sendto(datagram, destination)
        sent += len(batch) * _per(bundles)
        frame += 1
        wait = start + frame * period - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    ended = time.monotonic()
    out.put({"sent": sent, "seconds": ended - start, "ended": ended,
             "cpu_percent": 100.0 * (time.process_time() - cpu0) / (ended - start)})
    sock.close()


def step_raw(receiver: Receiver, rate: float, seconds: float, robots: int,
             bundles: bool = False) -> dict[str, Any]:
    ready, go, out = CONTEXT.Event(), CONTEXT.Event(), CONTEXT.Queue()
    sender = CONTEXT.Process(target=send_raw, args=(receiver.port, robots, rate, seconds, ready, go, out, bundles),
                             daemon=True)
    sender.start()
    try:
        if not ready.wait(20):
            raise RuntimeError("the raw UDP sender did not start")
        count0, _ = receiver.count()
        drops0, receiver_cpu0 = receiver.drops(), cpu_seconds(receiver.process.pid)
        started = time.monotonic()
        go.set()
        pub = out.get(timeout=3 * seconds + 30)
        receiver_cpu = cpu_seconds(receiver.process.pid) - receiver_cpu0
        window = time.monotonic() - started
        count, last = receiver.settle(pub["sent"] // _per(bundles), count0)
        drops = receiver.drops() - drops0
    finally:
        stop_children([sender])
    delivered = (count - count0) * _per(bundles)
    return {"offered_per_s": rate, "sent": pub["sent"], "achieved_per_s": pub["sent"] / pub["seconds"],
            "publisher_cpu_percent": pub["cpu_percent"], "delivered": delivered,
            "delivered_per_s": delivered / pub["seconds"], "lost": pub["sent"] - delivered,
            "loss_percent": 100.0 * (pub["sent"] - delivered) / max(1, pub["sent"]),
            "lag_s": max(0.0, last - pub["ended"]) if delivered else None,
            "receiver_cpu_percent": 100.0 * receiver_cpu / window, "receiver_socket_drops": drops}


def best(steps: list[dict[str, Any]]) -> float:
    """The highest offered rate delivered without loss (0 if none)."""
    return max((s["offered_per_s"] for s in steps if s["lost"] == 0), default=0.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[10000, 20000, 40000, 60000, 80000, 100000, 120000],
                        help="offered joint samples/s, one step each")
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each step")
    parser.add_argument("--robots", type=int, default=4, help="robots of 17 joints; a batch is one frame of each")
    parser.add_argument("--publishers", type=int, default=2,
                        help="publisher processes sharing the robots (one offers ~90k/s here beside the sink)")
    parser.add_argument("--bundles", action="store_true",
                        help="the sink sends a bundle per frame (bundle = true), the baseline the same bundles")
    parser.add_argument("--name", default="sink_throughput", help="results file name")
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    raw: list[dict[str, Any]] = []
    bus: list[dict[str, Any]] = []
    receiver = Receiver()
    try:
        with tempfile.TemporaryDirectory() as folder:
            for rate in args.rates:
                raw.append(step_raw(receiver, rate, args.seconds, args.robots, args.bundles))
                bus.append(step_sonibus(receiver, rate, args.seconds, args.robots, args.publishers, Path(folder),
                                        args.bundles))
                print(f"  {rate:>8.0f}/s: raw loss {raw[-1]['loss_percent']:.2f} %, "
                      f"sonibus loss {bus[-1]['loss_percent']:.2f} %", flush=True)
            unpaced = step_raw(receiver, 0.0, args.seconds, args.robots, args.bundles)  # raw UDP's ceiling here
    finally:
        receiver.close()
    result = {"joints": JOINTS, "robots": args.robots, "publishers": args.publishers, "seconds": args.seconds,
              "bundles": args.bundles,
              "machine": machine, "raw_udp": raw, "sonibus": bus, "raw_udp_unpaced": unpaced,
              "max_lossless_raw_per_s": best(raw), "max_lossless_sonibus_per_s": best(bus)}
    result["ratio_lossless"] = result["max_lossless_sonibus_per_s"] / max(1.0, result["max_lossless_raw_per_s"])
    at_least = "≥ " if raw and best(raw) == raw[-1]["offered_per_s"] else ""
    top = next((s for s in bus if s["offered_per_s"] == result["max_lossless_sonibus_per_s"]), None)
    sink_cpu = f", sink {top['sink_cpu_percent']:.0f} % CPU, lag {top['lag_s'] or 0:.2f} s" if top else ""
    shape = "a bundle per frame" if args.bundles else "a message per joint"
    result["summary"] = [{  # the row of bench/run.py's table
        "scenario": f"(b) lossless joint samples/s through one OSC sink process ({shape})",
        "sonibus": f"{result['max_lossless_sonibus_per_s']:,.0f}/s{sink_cpu}",
        "baseline": f"{at_least}{result['max_lossless_raw_per_s']:,.0f}/s raw UDP (unpaced "
                    f"{unpaced['delivered_per_s']:,.0f}/s)",
        "ratio": f"{result['ratio_lossless']:.2f}×", "goal": "≥ 100,000/s",
        "met": "yes" if result["max_lossless_sonibus_per_s"] >= 100_000 else "no"}]
    print(f"{'path':<8} {'offered/s':>9} {'put/s':>8} {'deliv/s':>8} {'loss %':>7} {'lag s':>6} "
          f"{'sink CPU%':>9} {'py/zrx %':>8} {'pub CPU%':>8} {'rx CPU%':>7} {'sink q.drop':>11}")
    for name, steps in (("raw", raw), ("sonibus", bus)):
        for s in steps:
            lag = f"{s['lag_s']:.2f}" if s["lag_s"] is not None else "-"
            sink_cpu = f"{s['sink_cpu_percent']:.0f}" if "sink_cpu_percent" in s else "-"
            qdrop = str(s["sink"].get("queue_dropped", "?")) if "sink" in s else "-"
            threads = s.get("sink_threads_cpu_percent")  # Python threads (named after the process) / Zenoh rx
            split = f"{threads.get('sonibus', 0):.0f}/{threads.get('rx', 0):.0f}" if threads else "-"
            print(f"{name:<8} {s['offered_per_s']:>9.0f} {s['achieved_per_s']:>8.0f} {s['delivered_per_s']:>8.0f} "
                  f"{s['loss_percent']:>7.2f} {lag:>6} {sink_cpu:>9} {split:>8} {s['publisher_cpu_percent']:>8.0f} "
                  f"{s['receiver_cpu_percent']:>7.0f} {qdrop:>11}")
    print(f"raw UDP unpaced: {unpaced['achieved_per_s']:.0f}/s sent, {unpaced['delivered_per_s']:.0f}/s "
          f"delivered, loss {unpaced['loss_percent']:.2f} % (sender CPU {unpaced['publisher_cpu_percent']:.0f} %, "
          f"receiver {unpaced['receiver_cpu_percent']:.0f} %)")
    print(f"max lossless: raw UDP {at_least}{result['max_lossless_raw_per_s']:.0f}/s, sonibus "
          f"{result['max_lossless_sonibus_per_s']:.0f}/s (ratio {result['ratio_lossless']:.2f}); goal ≥ 100000/s")
    write(args.name, result)
    print(machine)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks
    main()
