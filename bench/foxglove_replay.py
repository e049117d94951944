"""The Foxglove node's and the recorder's Python per bus message on a fixed workload
(issue 35): a simulated Pepper and the features node run until ``--frames`` frames
and their derived frames have been captured off the bus; the nodes' subscriptions
are then undeclared and the same captured messages are replayed, one bus message at
a time, into the Foxglove node on its server's loop (``_arrivals``: a client
subscribed to every channel reads them in another thread) and into the recorder's
``_record`` (its writer thread idle; the robot's info taken first, so each frame's
transforms are written beside it); each side's thread CPU (``time.thread_time``)
over the replay, per bus message. No Zenoh, no wake-ups: what the nodes' own code
costs a message.

    .venv/bin/python bench/foxglove_replay.py [--frames 500] [--rounds 3] [--before DIR]

``--before DIR``: DIR's ``sonibus`` (``git archive <commit> bus adapters schemas`` under
``DIR/sonibus``) replayed too, alternating with this tree round by round (each round a
process of its own). Writes bench/results/foxglove_replay.json.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent


def replay(frames: int) -> dict[str, float]:
    """One round in this process: µs of thread CPU per bus message, Foxglove's and the recorder's."""
    import aiohttp

    sys.path.insert(0, str(HERE.parent))
    from sonibus.adapters.features.config import FeaturesConfig
    from sonibus.adapters.features.processor import Features
    from sonibus.adapters.foxglove.server import FoxgloveConfig, FoxgloveServer
    from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
    from tests.conftest import Network, wait_for

    net = Network()
    captured: list[tuple[str, bytes]] = []
    net.sim()
    features = net.start(Features(FeaturesConfig(), name="features"))
    tap = net.bus("tap").session.declare_subscriber(
        "pepper/*", lambda s: captured.append((str(s.key_expr), s.payload.to_bytes())))
    fox = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    Recorder._write = lambda self: self.stopping.wait()  # type: ignore[method-assign]  # (_record called here)
    recorder = net.start(Recorder(RecorderConfig(path=os.path.join(tempfile.mkdtemp(), "r.mcap")), name="recorder"))
    received = [0]
    wait_for(lambda: fox.port, 5, "the Foxglove node listening")

    async def client() -> None:
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(f"ws://127.0.0.1:{fox.port}/", protocols=("foxglove.websocket.v1",))
            last = 0
            async for message in ws:
                if message.type == aiohttp.WSMsgType.TEXT:
                    data = json.loads(message.data)
                    if data.get("op") == "advertise":
                        subscriptions = [{"id": last + i + 1, "channelId": c["id"]}
                                         for i, c in enumerate(data["channels"])]
                        last += len(subscriptions)
                        await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))
                else:
                    received[0] += 1

    threading.Thread(target=lambda: asyncio.run(client()), daemon=True).start()
    wait_for(lambda: sum(k == "pepper/frame" for k, _ in captured) >= frames + 50, 120, "frames captured")
    deadline = time.monotonic() + 30
    while "pepper" not in recorder._views._arms:  # (what came live, the robot's info with it: its arms' views)
        assert time.monotonic() < deadline, "the recorder never got the robot's info"
        for item in recorder._queue.drain(timeout=0.5):
            recorder._take(*item)
    tap.undeclare()
    fox._streams.undeclare()
    recorder._streams.undeclare()
    features.stop()
    time.sleep(0.5)
    items = [(k, p) for k, p in captured if k in ("pepper/frame", "pepper/derived")][-2 * frames:]

    async def on_loop() -> float:
        start = time.thread_time()
        for item in items:
            fox._arrivals([item])
            await asyncio.sleep(0)  # (the loop writes to the client between messages, as live)
        return time.thread_time() - start

    before = received[0]
    fox_s = fox.web.submit(on_loop()).result(300)
    start = time.thread_time()
    for key, payload in items:
        recorder._record(key, payload, time.monotonic_ns())
    recorder_s = time.thread_time() - start
    wait_for(lambda: received[0] - before >= 40 * frames, 60, "the client reading what was replayed")
    return {"foxglove_us": fox_s / len(items) * 1e6, "recorder_us": recorder_s / len(items) * 1e6,
            "messages": len(items), "client_received": received[0] - before}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--before", default="", help="a folder holding an older tree's sonibus package")
    parser.add_argument("--name", default="foxglove_replay")
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)  # (a round, in this process)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(replay(args.frames)))
        os._exit(0)  # (the nodes' threads are not stopped: the round is over)
    trees = {"this tree": ""} | ({"before": args.before} if args.before else {})
    rounds: dict[str, list[dict[str, Any]]] = {name: [] for name in trees}
    for i in range(args.rounds):
        for name, folder in trees.items():
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (folder, os.environ.get("PYTHONPATH", ""))
                                                                if p))
            out = subprocess.run([sys.executable, __file__, "--one", "--frames", str(args.frames)], env=env,
                                 capture_output=True, text=True, timeout=600, check=True).stdout
            rounds[name].append(json.loads(out.strip().splitlines()[-1]))
            print(f"round {i + 1}, {name}: {rounds[name][-1]}", flush=True)
    result: dict[str, Any] = {"rounds": rounds, "load": os.getloadavg()[0]}
    for name, found in rounds.items():
        result[name] = {k: statistics.median(r[k] for r in found) for k in ("foxglove_us", "recorder_us")}
    if args.before:
        result["ratio"] = {k: result["this tree"][k] / result["before"][k] for k in ("foxglove_us", "recorder_us")}
    (HERE / "results" / f"{args.name}.json").write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k != "rounds"}, indent=1))


if __name__ == "__main__":
    main()
