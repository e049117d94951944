"""MIDI sink messages/s through JACK, beside python-rtmidi sending straight to
the same reader (issue 9, scenario d).

A private JACK server with the dummy driver (``jackd --no-realtime -n NAME
-d dummy -r 48000 -p 256``, as tests/midi/conftest.py runs it: no sound card,
a 5.3 ms period; always stopped at the end) carries everything. A reader
process opens the JACK MIDI input ``bench-reader:in`` and counts what arrives.

sonibus path, per step of the ramp: publisher process(es) act as fake robots
(serve ``botN/info``: 17 joints in 0..1, and put frames whose joints' 7-bit
values change every frame, so each joint sample is one control change) paced
one frame per robot at a time, as in ``sink_throughput.py``: each frame whole
on ``botN/frame``, then per joint, as a robot owner does; the ``midi`` sink
runs in its own process (``sonibus run``, ``api = "jack"``, ``connect =
"bench-reader:in"``; it takes the frames), fresh each step so its counters
(``sent``, ``queue_dropped``) are per step. Baseline, same run, interleaved: one process
sends the same control changes with python-rtmidi straight to the reader at
the same rate; then once unpaced, as fast as it goes (JACK's own limit: what
one client's port carries per period).

Delivered = counted by the reader. JACK drops what does not fit in a port's
buffer for one period, and libjack says so on the sender's stderr
("JackMidiBuffer::ReserveEvent ..."): counted as ``jack_overflows``; the
server's log counts xruns (a client not done within its period).

    .venv/bin/python bench/midi_rate.py [--rates 2000 5000 10000 20000 30000 40000 60000]
        [--seconds 3] [--robots 4] [--publishers 1]

Writes bench/results/midi_rate.json and prints a table.
"""

from __future__ import annotations

import argparse
import gc
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

from common import free_port, write
from sink_throughput import (
    CONTEXT,
    SONIBUS,
    Publishers,
    Receiver,
    cpu_seconds,
    cpu_times,
    sink_stats,
    stop_children,
    stop_process,
    thread_cpu,
    thread_share,
)

READER = "bench-reader"
OVERFLOW = "ReserveEvent"  # libjack: "JackMidiBuffer::ReserveEvent - the buffer does not have enough room ..."


def jack_up() -> bool:
    """Whether a JACK client can connect (libjack's complaints while it cannot are silenced)."""
    import rtmidi
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    try:
        probe = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "probe")
    except rtmidi.SystemError:
        return False
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)
    probe.delete()
    return True


def count_in(path: Path, text: str) -> int:
    """How often ``text`` occurs in the log file ``path`` so far (read in pieces: an
    overflowing sender writes tens of MB of complaints)."""
    if not path.exists():
        return 0
    found, tail, needle = 0, b"", text.encode()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            data = tail + chunk
            found += data.count(needle)
            tail = data[-(len(needle) - 1):]
    return found


def start_jack(log: Path) -> subprocess.Popen:
    """A private JACK server (dummy driver), made the default of this process and its children."""
    jackd = shutil.which("jackd")
    if jackd is None:
        sys.exit("jackd is not installed: apt-get install jackd2")
    name = f"sonibus-bench-{uuid.uuid4().hex[:8]}"
    os.environ["JACK_DEFAULT_SERVER"] = name
    os.environ["JACK_NO_START_SERVER"] = "1"
    with open(log, "w") as out:
        server = subprocess.Popen([jackd, "--no-realtime", "-n", name, "-d", "dummy", "-r", "48000", "-p", "256"],
                                  stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    deadline = time.monotonic() + 10
    while server.poll() is None and not jack_up():
        if time.monotonic() > deadline:
            stop_process(server, timeout=5)
            raise RuntimeError(f"jackd -n {name} did not come up in 10 s: {log.read_text()[-500:]}")
        time.sleep(0.05)
    if server.poll() is not None:
        raise RuntimeError(f"jackd -n {name} ended at start: {log.read_text()[-500:]}")
    return server


def stop_jack(server: subprocess.Popen) -> None:
    """Stop the server ``start_jack`` started, and remove what it leaves behind."""
    stop_process(server, timeout=5)
    for leftover in Path("/dev/shm").glob(f"jack_sem.*_{os.environ['JACK_DEFAULT_SERVER']}_*"):
        leftover.unlink(missing_ok=True)  # jackd 1.9 leaves its clients' semaphores


def read_midi(port: int, ready: Any) -> None:
    """Count MIDI messages arriving on JACK input ``bench-reader:in``; answer the control
    protocol of ``sink_throughput.receive`` on UDP ``port``."""
    import rtmidi
    gc.disable()
    state = [0, 0.0]

    def count(event: Any, data: Any) -> None:
        state[0] += 1
        state[1] = time.monotonic()

    midi_in = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, READER)
    midi_in.open_virtual_port("in")
    midi_in.set_callback(count)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    ready.set()
    try:
        while True:
            data, sender = sock.recvfrom(64)
            if data[1:2] == b"q":
                break
            sock.sendto(struct.pack("<qd", state[0], state[1]), sender)
    finally:
        midi_in.close_port()
        midi_in.delete()
        sock.close()


def send_cc(rate: float, seconds: float, stderr: str, ready: Any, go: Any, out: Any) -> None:
    """The baseline: control changes (channel 1, CC 20 on, value changing) straight to the
    reader, ``rate`` per second in batches of 17 (0: unpaced)."""
    import rtmidi
    gc.disable()
    fd = os.open(stderr, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 2)  # libjack reports overflows here
    midi_out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, "bench-sender")
    index = next(i for i, n in enumerate(midi_out.get_ports()) if n.startswith(f"{READER}:"))
    midi_out.open_port(index, "out")
    time.sleep(0.2)  # the connection is made by JACK between periods
    period = 17 / rate if rate else 0.0
    batches = round(seconds / period) if rate else sys.maxsize
    ready.set()
    go.wait(30)
    cpu0, start = time.process_time(), time.monotonic()
    sent = errors = batch = 0
    while batch < batches and time.monotonic() - start < (2.0 if rate else 1.0) * seconds:
        for j in range(17):
            try:
                midi_out.send_message([0xB0, 20 + j, (batch + j) % 128])
                sent += 1
            except Exception:
                errors += 1
        batch += 1
        wait = start + batch * period - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    ended = time.monotonic()
    out.put({"sent": sent, "errors": errors, "seconds": ended - start, "ended": ended,
             "cpu_percent": 100.0 * (time.process_time() - cpu0) / (ended - start)})
    time.sleep(0.3)  # what is still in rtmidi's ring buffer
    midi_out.close_port()
    midi_out.delete()


def step_direct(reader: Receiver, rate: float, seconds: float, folder: Path) -> dict[str, Any]:
    xruns0 = count_in(folder / "jackd.log", "XRun")
    ready, go, out = CONTEXT.Event(), CONTEXT.Event(), CONTEXT.Queue()
    stderr = folder / f"sender-{rate:g}.log"
    sender = CONTEXT.Process(target=send_cc, args=(rate, seconds, str(stderr), ready, go, out), daemon=True)
    sender.start()
    try:
        while not ready.wait(0.1):
            if not sender.is_alive():
                raise RuntimeError("the rtmidi sender did not start")
        count0, _ = reader.count()
        reader_cpu0, started = cpu_seconds(reader.process.pid), time.monotonic()
        go.set()
        sent = out.get(timeout=3 * seconds + 30)
        reader_cpu = cpu_seconds(reader.process.pid) - reader_cpu0
        window = time.monotonic() - started
        count, _ = reader.settle(sent["sent"], count0)
    finally:
        stop_children([sender])
    delivered = count - count0
    return {"offered_per_s": rate or None, "sent": sent["sent"], "send_errors": sent["errors"],
            "achieved_per_s": sent["sent"] / sent["seconds"], "sender_cpu_percent": sent["cpu_percent"],
            "delivered": delivered, "delivered_per_s": delivered / sent["seconds"], "lost": sent["sent"] - delivered,
            "loss_percent": 100.0 * (sent["sent"] - delivered) / max(1, sent["sent"]),
            "jack_overflows": count_in(stderr, OVERFLOW), "jack_xruns": count_in(folder / "jackd.log", "XRun") - xruns0,
            "reader_cpu_percent": 100.0 * reader_cpu / window}


def step_sink(reader: Receiver, rate: float, seconds: float, robots: int, publishers: int,
              folder: Path) -> dict[str, Any]:
    xruns0 = count_in(folder / "jackd.log", "XRun")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = folder / "midi.toml"
    config.write_text(f'[bus]\nmulticast = false\n\n[nodes.daw]\nadapter = "midi"\napi = "jack"\n'
                      f'connect = "{READER}:in"\nsubscribe = ["*/joints/*"]\n')
    log_path = folder / f"sink-{rate:g}.log"
    with open(log_path, "w") as log:
        sink = subprocess.Popen([SONIBUS, "-v", "run", str(config), "--no-multicast", "--listen", endpoint],
                                stdout=subprocess.DEVNULL, stderr=log, start_new_session=True)
    group = None
    try:
        group = Publishers(endpoint, publishers, robots, rate, seconds, value="ramp", info=True)
        group.wait_ready(sink)
        time.sleep(0.3)  # the warm-up frames have gone through
        count0, _ = reader.count()
        overflows0 = count_in(log_path, OVERFLOW)
        sink_cpu0, reader_cpu0 = cpu_times(sink.pid), cpu_seconds(reader.process.pid)
        threads0, started = thread_cpu(sink.pid), time.monotonic()
        pub = group.run(timeout=3 * seconds + 30)
        sink_user, sink_sys = (b - a for a, b in zip(sink_cpu0, cpu_times(sink.pid), strict=True))
        sink_cpu, reader_cpu = sink_user + sink_sys, cpu_seconds(reader.process.pid) - reader_cpu0
        window = time.monotonic() - started
        threads = thread_share(threads0, thread_cpu(sink.pid), window)
        count, last = reader.settle(pub["sent"], count0)
        jack_overflows = count_in(log_path, OVERFLOW) - overflows0
    finally:
        if group is not None:
            group.close()
        stop_process(sink)
    stats = sink_stats(log_path.read_text(errors="replace"))
    delivered = count - count0
    return {"offered_per_s": rate, "sent": pub["sent"], "achieved_per_s": pub["achieved_per_s"],
            "publisher_cpu_percent": pub["cpu_percent"], "delivered": delivered,
            "delivered_per_s": delivered / pub["seconds"], "lost": pub["sent"] - delivered,
            "loss_percent": 100.0 * (pub["sent"] - delivered) / max(1, pub["sent"]),
            "lag_s": max(0.0, last - pub["ended"]) if delivered else None, "jack_overflows": jack_overflows,
            "jack_xruns": count_in(folder / "jackd.log", "XRun") - xruns0,
            "sink_cpu_percent": 100.0 * sink_cpu / window, "sink_system_cpu_percent": 100.0 * sink_sys / window,
            "sink_threads_cpu_percent": threads,
            "reader_cpu_percent": 100.0 * reader_cpu / window, "sink": stats}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[2000, 5000, 10000, 20000, 30000, 40000, 60000],
                        help="offered joint samples/s (= control changes/s), one step each")
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each step")
    parser.add_argument("--robots", type=int, default=4, help="fake robots of 17 joints (MIDI channels 1..N)")
    parser.add_argument("--publishers", type=int, default=1,
                        help="publisher processes sharing the robots (each one more competes with JACK for the cores)")
    args = parser.parse_args()
    machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
    direct: list[dict[str, Any]] = []
    sink: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        server = start_jack(folder / "jackd.log")
        reader = None
        try:
            reader = Receiver(read_midi)
            for rate in args.rates:
                direct.append(step_direct(reader, rate, args.seconds, folder))
                sink.append(step_sink(reader, rate, args.seconds, args.robots, args.publishers, folder))
                print(f"  {rate:>6.0f}/s: rtmidi loss {direct[-1]['loss_percent']:.2f} %, sink loss "
                      f"{sink[-1]['loss_percent']:.2f} %, sink queue_dropped "
                      f"{sink[-1]['sink'].get('queue_dropped', '?')}", flush=True)
            unpaced = step_direct(reader, 0.0, args.seconds, folder)
        finally:
            if reader is not None:
                reader.close()
            stop_jack(server)
        xruns = (folder / "jackd.log").read_text(errors="replace").count("XRun")
    refused = [s["offered_per_s"] for s in sink if s["sink"].get("bad") or not s["delivered"]]
    if refused:  # a harness the gate refuses (it once served a partial robot info) must not read as a figure
        sys.exit(f"midi_rate: the sink refused input or delivered nothing at {refused} messages/s: "
                 f"{[s['sink'] for s in sink if s['offered_per_s'] == refused[0]]}")
    no_drop = [s for s in sink if s["sink"].get("queue_dropped", 1) == 0]
    result = {"joints": 17, "robots": args.robots, "seconds": args.seconds, "machine": machine,
              "jack": "dummy driver, 48000 Hz, 256 frames per period", "jack_xruns": xruns,
              "rtmidi_direct": direct, "rtmidi_unpaced": unpaced, "sonibus": sink,
              "max_delivered_no_queue_drop_per_s": max((s["delivered_per_s"] for s in no_drop), default=0.0),
              "max_lossless_sonibus_per_s": max((s["offered_per_s"] for s in sink if s["lost"] == 0), default=0.0),
              "max_lossless_direct_per_s": max((s["offered_per_s"] for s in direct if s["lost"] == 0), default=0.0)}
    result["ratio_lossless"] = result["max_lossless_sonibus_per_s"] / max(1.0, result["max_lossless_direct_per_s"])
    at_most = "≤ " if direct and result["max_lossless_direct_per_s"] == direct[-1]["offered_per_s"] else ""
    result["summary"] = [{  # the row of bench/run.py's table
        "scenario": "(d) MIDI sink messages/s through JACK, no queue drop",
        "sonibus": f"{result['max_delivered_no_queue_drop_per_s']:,.0f}/s delivered; lossless up to "
                   f"{result['max_lossless_sonibus_per_s']:,.0f}/s",
        "baseline": f"rtmidi straight: lossless up to {result['max_lossless_direct_per_s']:,.0f}/s"
                    f"{' (top step)' if at_most else ''}; "
                    f"unpaced {unpaced['delivered_per_s']:,.0f}/s delivered",
        "ratio": f"{at_most}{result['ratio_lossless']:.2f}× lossless"}]
    print(f"{'path':<8} {'offered/s':>9} {'sent/s':>8} {'deliv/s':>8} {'loss %':>7} {'ovf/xrun':>8} "
          f"{'sink CPU%':>9} {'py/zrx %':>8} {'rdr CPU%':>8} {'q.drop':>7}")
    for label, steps in (("rtmidi", [*direct, unpaced]), ("sonibus", sink)):
        for s in steps:
            threads = s.get("sink_threads_cpu_percent")
            split = f"{threads.get('sonibus', 0):.0f}/{threads.get('rx', 0):.0f}" if threads else "-"
            offered = f"{s['offered_per_s']:.0f}" if s["offered_per_s"] else "unpaced"
            print(f"{label:<8} {offered:>9} {s['achieved_per_s']:>8.0f} {s['delivered_per_s']:>8.0f} "
                  f"{s['loss_percent']:>7.2f} {str(s['jack_overflows']) + '/' + str(s['jack_xruns']):>8} "
                  f"{format(s['sink_cpu_percent'], '.0f') if 'sink' in s else '-':>9} {split:>8} "
                  f"{s['reader_cpu_percent']:>8.0f} {s['sink'].get('queue_dropped', '?') if 'sink' in s else '-':>7}")
    print(f"sink: {result['max_delivered_no_queue_drop_per_s']:.0f} messages/s delivered with no queue drop "
          f"(lossless up to {result['max_lossless_sonibus_per_s']:.0f}/s); rtmidi straight: lossless up to "
          f"{result['max_lossless_direct_per_s']:.0f}/s, unpaced {unpaced['delivered_per_s']:.0f}/s delivered of "
          f"{unpaced['achieved_per_s']:.0f}/s sent; {xruns} JACK xruns")
    write("midi_rate", result)
    print(machine)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # a kill still runs the finally blocks (jackd)
    main()
