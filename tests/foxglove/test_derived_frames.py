"""Issue 35: derived values come as derived frames (``<robot>/derived``); a Foxglove client
sees what it saw when each came on its own key: a channel per derived key with the
derived sample schema, messages ``{t, seq, v}``, and no channel of the frame."""

from __future__ import annotations

import json

import aiohttp
import jsonschema

from sonibus import schemas
from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.adapters.foxglove.server import FoxgloveConfig, FoxgloveServer

from .test_server import connect, run


def test_a_client_gets_a_channel_per_derived_key_as_before(net):
    server = net.start(FoxgloveServer(FoxgloveConfig(listen="127.0.0.1:0"), name="foxglove"))
    net.sim("pepper", rate_hz=50)
    net.start(Features(FeaturesConfig(robots="pepper", max_age_ms=0), name="features"))
    wanted = {"pepper/derived/qom/Body", "pepper/derived/hand/R", "pepper/derived/velocity/HeadYaw"}

    async def scenario() -> list:
        async with aiohttp.ClientSession() as session:
            client = await connect(session, server.port)
            await client.until(lambda _: wanted <= client.channels.keys())
            for topic in wanted:
                channel = client.channels[topic]
                assert (channel["schemaName"], channel["encoding"]) == ("sonibus.v1.derived_sample", "json")
                assert json.loads(channel["schema"]) == schemas.load("derived_sample")
            assert "pepper/derived" not in client.channels
            await client.subscribe({1: "pepper/derived/qom/Body", 2: "pepper/derived/hand/R"})
            return await client.until(lambda got: {s for s, _, _ in got} == {1, 2} and len(got) >= 10)

    found = run(scenario())
    by_seq: dict[int, dict] = {}
    for subscription, _, payload in found:
        message = json.loads(payload)
        jsonschema.validate(message, schemas.load("derived_sample"))
        assert set(message) == {"t", "seq", "v"}
        assert isinstance(message["v"], list if subscription == 2 else float) and (
            subscription == 1 or len(message["v"]) == 3)
        by_seq.setdefault(message["seq"], {})[subscription] = message["t"]
    assert any(len(ts) == 2 and len(set(ts.values())) == 1 for ts in by_seq.values())  # one frame's t on both
