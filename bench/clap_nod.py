"""Sound to movement: a clap into a JACK input → the robot's ``joints/set`` carried out,
through examples/clap-nod.toml's nodes (jack → ``pepper/audio/speaker`` → hear's onset →
the map ``nod`` → the sim Pepper's owner), beside the same ``joints/set`` sent straight
with ``client.ask`` in the same run (the owner's part of the path).

A private JACK server with the dummy driver (``-p 256``: 5.3 ms periods) and a client
``clapper`` that plays one impulse when asked; the robot on one Zenoh session, the other
nodes on another (two "machines" on loopback). Each clap waits for the nod's return to 0
before the next. Latency: the clap's JACK block (wall clock) to the owner's ``command``
event (``t`` taken after it carried the command out).

    .venv/bin/python bench/clap_nod.py [--claps 40]

Writes bench/results/clap_nod.json and prints p50/p99 in ms and their ratio.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from common import free_port, latency_stats, write
from midi_rate import start_jack, stop_jack

from sonibus.adapters.hear import Hear
from sonibus.adapters.jack import JackBridge
from sonibus.adapters.map import MapNode
from sonibus.adapters.sim import SimRobot
from sonibus.bus import Bus, BusConfig, client, codec, config, keys, open_session

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "clap-nod.toml"


class Commands:
    """The owner's ``command`` events (joints/set), as they come."""

    def __init__(self, bus: Bus) -> None:
        self.seen: list[dict[str, Any]] = []
        self.changed = threading.Condition()
        self.subscriber = bus.session.declare_subscriber(keys.event("pepper", "command"), self._take)

    def _take(self, sample: Any) -> None:
        event = codec.decode(sample.payload.to_bytes())
        if event.get("verb") == "joints/set":
            with self.changed:
                self.seen.append(event)
                self.changed.notify_all()

    def next(self, count: int, angle: float, speed: float, timeout: float = 5.0) -> dict[str, Any]:
        """The first event after the first ``count`` that moved HeadPitch to ``angle`` at ``speed``."""
        def found() -> dict[str, Any] | None:
            return next((e for e in self.seen[count:] if e["args"].get("angles") == [angle]
                         and e["args"].get("speed") == speed), None)
        with self.changed:
            if not self.changed.wait_for(found, timeout):
                raise RuntimeError(f"no joints/set to {angle} within {timeout} s")
            return found()  # type: ignore[return-value]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--claps", type=int, default=40)
    args = parser.parse_args()
    import jack

    folder = Path(tempfile.mkdtemp(prefix="sb-clap-"))
    server = start_jack(folder / "jackd.log")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robot_session = open_session(BusConfig(multicast=False, listen=(endpoint,)))
    node_session = open_session(BusConfig(multicast=False, connect=(endpoint,)))
    clapped: list[float] = []
    played = [0, 0]  # frames JACK played, and how many at the last clap
    armed = threading.Event()
    clapper = jack.Client("clapper", no_start_server=True)
    port = clapper.outports.register("clap")

    def process(frames: int) -> None:
        out = port.get_array()
        out[:] = 0.0
        if armed.is_set():
            armed.clear()
            out[0] = 0.9
            clapped.append(time.time())
            played[1] = played[0]
        played[0] += frames

    clapper.set_process_callback(process)
    clapper.activate()
    nodes: list[Any] = []
    try:
        specs = config.load(EXAMPLE).nodes
        robot = specs["robot"]
        robot = config.NodeSpec(robot.name, robot.adapter, {**robot.options, "speaker": False, "body_sound": False},
                                robot.where, robot.lines).build(SimRobot)
        robot.start(Bus(robot_session, node="robot"))
        nodes.append(robot)
        jack_spec = specs["jack"]
        for adapter in (config.NodeSpec(jack_spec.name, jack_spec.adapter,
                                        {**jack_spec.options, "connect_inputs": ["clapper:clap"]},
                                        jack_spec.where, jack_spec.lines).build(JackBridge),
                        specs["ears"].build(Hear), specs["moves"].build(MapNode)):
            adapter.start(Bus(node_session, node=adapter.name))
            nodes.append(adapter)
        moves = nodes[-1]
        watch = Bus(node_session, node="bench")
        commands = Commands(watch)
        deadline = time.monotonic() + 10
        while not ("pepper" in moves._ranges and "pepper/derived/onset/speaker" in moves._ranges["pepper"].derived):
            if time.monotonic() > deadline:
                raise RuntimeError("the map node did not learn the onset's range in 10 s")
            time.sleep(0.05)

        direct = []  # baseline: joints/set sent straight, to the owner's event
        for i in range(args.claps):
            count = len(commands.seen)
            sent = time.time()
            client.ask(watch, "pepper", "joints/set", {"names": ["HeadPitch"], "angles": [0.3 * (i % 2)],
                                                       "speed": 0.5}, lambda outcome: None, 2.0)
            direct.append(commands.next(count, 0.3 * (i % 2), 0.5)["t"] - sent)  # (the map's go at 0.6)
            time.sleep(0.05)
        client.send_command(watch, "pepper", "joints/set", {"names": ["HeadPitch"], "angles": [0.0]})
        time.sleep(0.3)

        nod = []
        for _ in range(args.claps):
            count = len(commands.seen)
            armed.set()
            down = commands.next(count, 0.3, 0.6)
            nod.append(down["t"] - clapped[-1])
            commands.next(count, 0.0, 0.6)  # (its return to 0, after the onset's hold)
            deadline = time.monotonic() + 5
            while played[0] - played[1] < 0.3 * 48000:  # (past the onset's hold by JACK's clock, which can lag)
                if time.monotonic() > deadline:
                    raise RuntimeError("JACK's clock did not run 0.3 s in 5 s")
                time.sleep(0.01)
        machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}"
        result: dict[str, Any] = {"claps": args.claps, "machine": machine, "clap_to_joints_set": latency_stats(nod),
                                  "joints_set_direct": latency_stats(direct), "period_ms": 256 / 48}
        a, b = result["clap_to_joints_set"], result["joints_set_direct"]
        result["summary"] = [{
            "scenario": "clap into JACK → robot's joints/set carried out (jack → hear → map → owner), p50 / p99",
            "sonibus": f"{a['p50_us'] / 1000:.1f} ms / {a['p99_us'] / 1000:.1f} ms",
            "baseline": f"{b['p50_us'] / 1000:.1f} ms / {b['p99_us'] / 1000:.1f} ms (joints/set sent straight)",
            "ratio": f"{a['p50_us'] / b['p50_us']:.1f}× / {a['p99_us'] / b['p99_us']:.1f}×",
            "goal": "≤ 100 ms", "met": "yes" if a["p99_us"] <= 100_000 else "no"}]
        print(machine)
        print(f"clap → joints/set  p50 {a['p50_us'] / 1000:6.1f} ms  p99 {a['p99_us'] / 1000:6.1f} ms  "
              f"max {a['max_us'] / 1000:6.1f} ms  ({a['n']} claps)")
        print(f"joints/set direct  p50 {b['p50_us'] / 1000:6.1f} ms  p99 {b['p99_us'] / 1000:6.1f} ms")
        write("clap_nod", result)
    finally:
        for node in reversed(nodes):
            node.stop()
        clapper.deactivate()
        clapper.close()
        node_session.close()
        robot_session.close()
        stop_jack(server)


if __name__ == "__main__":
    main()
