"""A map's output reaches sinks built before maps existed, with no change to them: the
recorder writes it into its MCAP file (read back here with the mcap package's own reader),
Foxglove's server advertises it and sends it to a client."""

from __future__ import annotations

import json
import threading
import time

import aiohttp
from mcap.reader import make_reader

from sonibus.adapters.foxglove.server import FoxgloveConfig, FoxgloveServer
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig

from ..features.conftest import model_info
from ..foxglove.test_server import connect, run
from ..recorder.conftest import settle
from .conftest import map_node, pose

TEXT = '''[nodes.sound]
adapter = "map"
[nodes.sound.maps.head]
source = "pepper/joints/HeadYaw"
from = [-1, 1]
to = [0, 127]
unit = "cc"
'''


def test_the_recorder_writes_a_maps_output_as_any_derived_value(net, owner, tmp_path):
    fake = owner("pepper", model_info("pepper"))
    path = tmp_path / "show.mcap"
    recorder = net.start(Recorder(RecorderConfig(path=str(path)), name="logger"))
    node = map_node(net, TEXT)
    sent = {}
    deadline = time.monotonic() + 10
    while node.stats["sent"] < 20:
        assert time.monotonic() < deadline, dict(node.stats)
        t = time.time()
        yaw = -1 + (len(sent) % 20) / 10
        fake.frame(t, pose(HeadYaw=yaw))
        sent[t] = 127 * (yaw + 1) / 2
        time.sleep(0.02)
    settle(lambda: recorder.stats["received"])  # (the last outputs in flight)
    recorder.stop()
    with path.open("rb") as file:
        found = [(channel.topic, json.loads(message.data))
                 for _, channel, message in make_reader(file).iter_messages(topics=["sound/derived/map/head"])]
    assert len(found) >= 15, len(found)
    for _, message in found:
        assert abs(message["v"] - sent[message["t"]]) < 1e-9, message
    with path.open("rb") as file:  # and what describes it, for Foxglove's panels and for replay
        described = [json.loads(message.data) for _, _, message
                     in make_reader(file).iter_messages(topics=["sound/info/derived"])]
    assert described and described[-1]["derived"][0]["name"] == "map/head", described
    assert (described[-1]["derived"][0]["min"], described[-1]["derived"][0]["max"]) == (0, 127)


def test_foxglove_advertises_a_maps_output_and_sends_it(net, owner):
    """A real WebSocket client speaking Foxglove's protocol (tests/foxglove's)."""
    fake = owner("pepper", model_info("pepper"))
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    node = map_node(net, TEXT)
    stop = threading.Event()

    def frames() -> None:
        i = 0
        while not stop.is_set():
            fake.frame(time.time(), pose(HeadYaw=-1 + (i % 20) / 10))
            i += 1
            stop.wait(0.02)

    async def scenario() -> list:
        async with aiohttp.ClientSession() as session:
            client = await connect(session, server.port)
            await client.until(lambda _: "sound/derived/map/head" in client.channels)
            await client.until(lambda _: "sound/info/derived" in client.channels)  # (what describes it)
            await client.subscribe({1: "sound/derived/map/head"})
            return await client.until(lambda got: len(got) >= 10)

    feeder = threading.Thread(target=frames, daemon=True)
    feeder.start()
    try:
        found = run(scenario())
    finally:
        stop.set()
        feeder.join()
    values = [json.loads(payload)["v"] for _, _, payload in found]
    assert all(0 <= v <= 127 for v in values) and len(set(values)) > 3, values
    assert node.stats["sent"] >= 10
