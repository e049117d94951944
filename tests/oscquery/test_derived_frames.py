"""Issue 35: derived values come as derived frames (``<robot>/derived``); an OSCQuery client
LISTENing to a derived value's address gets it as before, one OSC message per value, at its
own address, with the numbers it holds (a hand position: three)."""

from __future__ import annotations

from pythonosc.osc_message import OscMessage

from sonibus.adapters.features import Features, FeaturesConfig

from ..conftest import wait_for


def test_listen_streams_derived_values_of_derived_frames(served, websocket):
    served.net.start(Features(FeaturesConfig(robots="pepper", max_age_ms=0), name="features"))
    served.wait_node("/pepper/derived/hand/R")
    client = websocket(served.url)
    client.send({"COMMAND": "LISTEN", "DATA": "/pepper/derived/hand/R"})
    client.send({"COMMAND": "LISTEN", "DATA": "/pepper/derived/qom/Body"})

    def received() -> list[OscMessage]:
        return [OscMessage(m) for m in list(client.messages) if isinstance(m, bytes)]
    wait_for(lambda: {m.address for m in received()} == {"/pepper/derived/hand/R", "/pepper/derived/qom/Body"}
             and len(received()) >= 10, what="both derived values streamed")
    for message in received():
        assert len(message.params) == (3 if message.address.endswith("/hand/R") else 1)
        assert all(isinstance(p, float) for p in message.params)
