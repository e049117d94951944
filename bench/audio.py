"""Audio through the bus (issue 18): JACK input → the robot's speaker buffer, and the
robot's microphones → JACK output, beside the same PCM over plain UDP between the
same processes.

A private JACK server (dummy driver, 48 kHz, 256-frame periods) runs; this process is
the sound tool, a JACK client playing a 440 Hz sine into the ``jack`` adapter's inputs.
Two processes, one Zenoh session each on loopback TCP: the ``jack`` adapter
(``JackBridge``, its defaults: 10 ms chunks, 60 ms jitter buffer), and the simulated
Pepper (``sim``: its speaker's jitter buffer at the default 100 ms, its microphones
the servo whine of its idle motion, 16 kHz mono in 20 ms chunks) — or, for the
speaker, naoqi-sim and the ``naoqi`` adapter owning it over libqi, in one process
(its speaker's jitter buffer at the default 100 ms, ceiling 0.25). Each phase runs
one stream one way:

- speaker: JACK input → chunks → the robot's speaker buffer (sim; naoqi);
- mic: the robot's whine → chunks → the ``jack`` adapter's buffer → JACK output.

Latency = arrival at the receiving worker (where a chunk enters the jitter buffer)
− the chunk's ``t`` (the wall clock of its first frame; one host, one clock), so it
includes the chunk's own length and the sender's cutting; "to played" adds what the
jitter buffer held ahead of it (when its first frame is played). Dropouts: the
receiving jitter buffer's underruns and gaps, per minute. CPU: each process's user +
system time over the phase, % of one core (the robot's includes its 100 Hz frames,
the same in both modes). Baseline, same run: the same chunks (same payloads, same
workers) sent over a plain UDP socket instead of Zenoh.

    .venv/bin/python bench/audio.py [--seconds 20]

Writes bench/results/audio.json.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import resource
import socket
import subprocess
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np
from common import free_port, latency_stats, write

RATE, PERIOD = 48000, 256
WARMUP_S = 2.0  # connecting, the jitter buffers filling: left out
MODES = ("sonibus", "udp")
STREAMS = {  # name → (robot, direction, what is measured)
    "speaker_sim": ("sim", "speaker", "JACK input → robot speaker buffer (sim)"),
    "speaker_naoqi": ("naoqi", "speaker", "JACK input → robot speaker buffer (naoqi adapter, naoqi-sim)"),
    "mic_sim": ("sim", "mic", "robot mic (sim) → JACK output buffer"),
}


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


class _Tee:
    """A publisher's ``put`` over Zenoh (mode ``sonibus``) or as one UDP datagram (``udp``)."""

    def __init__(self, publisher: Any, mode: str, key: str, port: int) -> None:
        self.publisher, self.mode, self.port = publisher, mode, port
        self.prefix = key.encode() + b"\0"
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def put(self, payload: bytes) -> None:
        if self.mode == "sonibus":
            self.publisher.put(payload)
        else:
            self.sock.sendto(self.prefix + payload, ("127.0.0.1", self.port))


class _Measured:
    """A receiving worker's queue, timing each chunk it hands over (and what the buffer holds then)."""

    def __init__(self, queue: Any, buffer: Any, start: float) -> None:
        self.queue, self.buffer, self.start = queue, buffer, start
        self.arrival: list[float] = []
        self.played: list[float] = []

    def get(self, timeout: float | None = None) -> Any:
        item = self.queue.get(timeout)
        return self._time([item])[0] if item is not None else None

    def drain(self, timeout: float | None = None) -> list[Any]:
        return self._time(self.queue.drain(timeout))

    def _time(self, items: list[Any]) -> list[Any]:
        from sonibus.bus import decode
        now = time.time()
        ahead = self.buffer.buffered / self.buffer.rate
        for _key, payload in items:
            t = decode(payload)["t"]
            if t >= self.start:
                self.arrival.append(now - t)
                self.played.append(now - t + ahead)
        return items

    def __getattr__(self, name: str) -> Any:
        return getattr(self.queue, name)


def _udp_into(queue: Any, port: int, stop: threading.Event) -> threading.Thread:
    """Datagrams on ``port`` into ``queue`` as ``(key, payload)``, the way a subscription fills it."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(0.2)

    def run() -> None:
        while not stop.is_set():
            try:
                data = sock.recv(65536)
            except TimeoutError:
                continue
            key, _, payload = data.partition(b"\0")
            queue.put((key.decode(), payload))
        sock.close()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def _robot(robot: str, speaker: bool, bus: Any) -> tuple[Any, Any]:
    """The robot's node (started) and what it plays or hears with: ``(node, speaker or mic)``;
    ``naoqi``: naoqi-sim in this process and the naoqi adapter owning it."""
    from sonibus.adapters.sim import SimConfig, SimRobot
    if robot == "sim":
        node = SimRobot(SimConfig(robot="pepper", idle=True, body_sound=not speaker, speaker=speaker), name="sim")
        node.start(bus)
        return node, node.speaker if speaker else node.mic
    from sonibus.adapters.naoqi import NaoqiConfig, NaoqiRobot
    from sonibus.adapters.sim.naoqi import FakeNaoqi, FakeNaoqiConfig
    fake = FakeNaoqi(FakeNaoqiConfig(listen=f"tcp://127.0.0.1:{free_port()}", rate_hz=50, idle=True)).start()
    node = NaoqiRobot(NaoqiConfig(robot="pepper", url=fake.url, rate_hz=50), name="pepper")
    node.start(bus)
    node.fake = fake  # (stopped after the node)
    if not node.speaker.available.wait(20):
        raise SystemExit("the naoqi adapter found no ALAudioDevice")
    return node, node.speaker


def _side(role: str, robot: str, direction: str, mode: str, endpoint: str, server: str, ports: dict[str, int],
          seconds: float, ready: Any, go: Any, out: Any) -> None:
    """One process: the ``jack`` adapter (role ``jack``) or the robot (``robot``: ``sim`` or ``naoqi``)."""
    os.environ["JACK_DEFAULT_SERVER"] = server
    from sonibus.adapters.jack import JackBridge, JackConfig
    from sonibus.bus import Bus, BusConfig, open_session
    role_bus = {"listen": (endpoint,)} if role == "jack" else {"connect": (endpoint,)}
    session = open_session(BusConfig(multicast=False, **role_bus))
    bus = Bus(session, node=f"bench-{role}")
    stop = threading.Event()
    speaker = direction == "speaker"
    if role == "jack":
        node: Any = JackBridge(JackConfig(robot="pepper", to_robot=speaker, from_robot=not speaker, outputs=1),
                               name="jack")
        node.start(bus)
        owner = node
    else:
        node, owner = _robot(robot, speaker, bus)
    sending = (role == "jack") == speaker
    measured = None
    if sending:
        owner._publisher = _Tee(owner._publisher, mode, f"pepper/audio/{direction}", ports[direction])
    elif mode == "udp":
        _udp_into(owner._queue, ports[direction], stop)
    ready.set()
    go.wait(30)
    start_wall = time.time() + WARMUP_S
    time.sleep(WARMUP_S)
    start_cpu = _cpu()
    if not sending:
        buffer = node._buffer if role == "jack" else owner.buffer
        measured = owner._queue = _Measured(owner._queue, buffer, start_wall)
        before = dict(buffer.stats)
    time.sleep(seconds)
    report: dict[str, Any] = {"role": role, "cpu_pct": 100 * (_cpu() - start_cpu) / seconds}
    if measured is not None:
        stats = {k: v - before[k] for k, v in buffer.stats.items()}
        report.update(arrival=measured.arrival, played=measured.played, buffer=stats)
    stop.set()
    node.stop()
    if hasattr(node, "fake"):
        node.fake.stop()
    session.close()
    out.put(report)


def _tone(server: str) -> Any:
    """This process's JACK client: a sine into two output ports."""
    import jack
    client = jack.Client("bench-tone", no_start_server=True, servername=server)
    ports = [client.outports.register(f"out_{i}") for i in (1, 2)]
    phase = [0.0]

    @client.set_process_callback
    def process(frames: int) -> None:
        n = phase[0] + np.arange(frames)
        wave = (0.3 * np.sin(2 * np.pi * 440.0 * n / RATE)).astype(np.float32)
        phase[0] += frames
        for port in ports:
            port.get_array()[:] = wave

    client.activate()
    return client


def phase(robot: str, direction: str, mode: str, server: str, seconds: float) -> dict[str, Any]:
    ctx = mp.get_context("spawn")  # never fork a process that has opened a Zenoh session
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    ports = {"speaker": free_port(socket.SOCK_DGRAM), "mic": free_port(socket.SOCK_DGRAM)}
    go, out = ctx.Event(), ctx.Queue()
    readies, procs = [], []
    for role in ("jack", "robot"):
        ready = ctx.Event()
        proc = ctx.Process(target=_side,
                           args=(role, robot, direction, mode, endpoint, server, ports, seconds, ready, go, out),
                           daemon=True)  # (ended with this process if a phase fails)
        proc.start()
        if not ready.wait(30):
            raise SystemExit(f"the {role} process did not start")
        readies.append(ready)
        procs.append(proc)
    tone = _tone(server)
    if direction == "speaker":
        for i in (1, 2):
            tone.connect(f"bench-tone:out_{i}", f"sonibus:speaker_{i}")
    go.set()
    reports = {r["role"]: r for r in (out.get(timeout=seconds + 60) for _ in procs)}
    for proc in procs:
        proc.join(10)
    tone.deactivate()
    tone.close()
    receiver = reports["robot" if direction == "speaker" else "jack"]
    buffer = receiver["buffer"]
    return {"arrival": latency_stats(receiver["arrival"]), "to_played": latency_stats(receiver["played"]),
            "chunks": len(receiver["arrival"]), "buffer": buffer,
            "dropouts_per_min": (buffer["underruns"] + buffer["gaps"]) * 60 / seconds,
            "cpu_jack_pct": reports["jack"]["cpu_pct"], "cpu_robot_pct": reports["robot"]["cpu_pct"]}


def _ms(us: float) -> str:
    return f"{us / 1000:.1f} ms"


def summary(runs: dict[str, dict[str, Any]]) -> list[dict[str, str]]:
    rows = []
    for stream, (_robot_kind, _direction, name) in STREAMS.items():
        bus, udp = runs[stream]["sonibus"], runs[stream]["udp"]
        rows.append({"scenario": f"audio: {name}, p50 / p99 (to played)",
                     "sonibus": f"{_ms(bus['arrival']['p50_us'])} / {_ms(bus['arrival']['p99_us'])} "
                                f"({_ms(bus['to_played']['p50_us'])})",
                     "baseline": f"{_ms(udp['arrival']['p50_us'])} / {_ms(udp['arrival']['p99_us'])} "
                                 f"({_ms(udp['to_played']['p50_us'])}) (UDP)",
                     "ratio": f"{bus['arrival']['p50_us'] / udp['arrival']['p50_us']:.1f}×", "goal": "", "met": ""})
        rows.append({"scenario": f"audio: {name}, dropouts/min; CPU jack / robot process",
                     "sonibus": f"{bus['dropouts_per_min']:.1f}; {bus['cpu_jack_pct']:.1f} % / "
                                f"{bus['cpu_robot_pct']:.1f} %",
                     "baseline": f"{udp['dropouts_per_min']:.1f}; {udp['cpu_jack_pct']:.1f} % / "
                                 f"{udp['cpu_robot_pct']:.1f} % (UDP)",
                     "ratio": "", "goal": "no dropouts", "met": "yes" if bus["dropouts_per_min"] == 0 else "no"})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="measured time per phase")
    args = parser.parse_args()
    server = f"bench-{uuid.uuid4().hex[:8]}"
    jackd = subprocess.Popen(["jackd", "--no-realtime", "-n", server, "-d", "dummy", "-r", str(RATE),
                              "-p", str(PERIOD)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    try:
        time.sleep(1.0)  # (jackd takes clients within a second; the first phase's open fails loudly if not)
        runs: dict[str, dict[str, Any]] = {}
        for stream, (robot, direction, _name) in STREAMS.items():
            for mode in MODES:
                runs.setdefault(stream, {})[mode] = result = phase(robot, direction, mode, server, args.seconds)
                print(f"{stream:14} {mode:8} arrival p50 {_ms(result['arrival']['p50_us'])} "
                      f"p99 {_ms(result['arrival']['p99_us'])}, to played p50 {_ms(result['to_played']['p50_us'])}, "
                      f"dropouts/min {result['dropouts_per_min']:.1f}, CPU jack {result['cpu_jack_pct']:.1f} % "
                      f"robot {result['cpu_robot_pct']:.1f} %", flush=True)
    finally:
        jackd.terminate()
        jackd.wait(10)
        for leftover in Path("/dev/shm").glob(f"jack_sem.*_{server}_*"):
            leftover.unlink(missing_ok=True)
    write("audio", {"machine": machine, "seconds": args.seconds, "rate": RATE, "period": PERIOD, "runs": runs,
                    "summary": summary(runs)})


if __name__ == "__main__":
    main()
