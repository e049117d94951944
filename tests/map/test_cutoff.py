"""The issue's cutoff example end to end: frames → features → map node → OSC sink →
a UDP socket, and each value received is the curve's formula applied to the hand
height of the same frame (matched by its ``t``), smoothed as documented."""

from __future__ import annotations

import math
import socket
import threading

import pytest
from pythonosc.osc_message import OscMessage

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import codec, keys

from ..conftest import free_port, wait_for
from ..features.conftest import model_info
from ..features.test_processor import start
from ..osc.pd import Datagrams, Patch, errors, osc_input, printed, start_pd
from .conftest import ROOT, cutoff_example, map_node, sweep


def test_the_cutoff_example_is_at_most_8_lines_and_the_shipped_example_holds_it():
    lines = cutoff_example().strip().splitlines()
    assert len(lines) <= 8, lines
    assert cutoff_example() in (ROOT / "examples" / "mapping.toml").read_text(encoding="utf-8")


def test_pd_gets_sound_cutoff_as_the_exp_curve_of_the_hand_height_smoothed(net, owner):
    fake = owner("pepper", model_info("pepper"))
    start(net, robots="pepper", features=("hand",))
    node = map_node(net, cutoff_example())
    receiver = Datagrams()
    watch = net.bus("watch")
    heights: list[tuple[float, float]] = []
    used: set[float] = set()  # the t of every output the map put on the bus
    lock = threading.Lock()

    def take(sample):
        message = codec.decode(sample.payload.to_bytes())
        with lock:
            if str(sample.key_expr) == "pepper/derived":  # (a derived frame: every value of one frame)
                heights.extend((message["t"], v[2]) for n, v in zip(message["names"], message["v"], strict=True)
                               if n == "hand/R")
            else:
                used.add(message["t"])

    subscriber = watch.session.declare_subscriber("pepper/derived", take)
    outputs = watch.session.declare_subscriber("sound/derived/map/cutoff", take)
    try:
        net.start(OscSink(OscSinkConfig(subscribe=("sound/derived/**",), targets=(receiver.target,),
                                        derived_address="/{robot}/{name}", extra=("t",)), name="pd"))
        box = []
        sweep(fake, until=lambda: box.extend(watch.query(keys.derived_info("pepper"), timeout=0.1)) or box)
        hand = next(d for d in box[0]["derived"] if d["key"] == "pepper/derived/hand/R")
        low, high = hand["box"]["min"][2], hand["box"]["max"][2]
        sweep(fake, until=lambda: node.stats["sent"] > 0)
        sweep(fake, 120)
        wait_for(lambda: len(heights) >= 120, what="the hand heights")
        wait_for(lambda: max(heights)[0] in {OscMessage(d).params[1] for d in receiver.data()},
                 what="the last hand height's cutoff in the receiver")
    finally:
        subscriber.undeclare()
        outputs.undeclare()
        receiver.close()
    received = [OscMessage(d) for d in receiver.data()]
    assert {m.address for m in received} == {"/sound/cutoff"}
    by_t = {m.params[1]: m.params[0] for m in received}
    with lock:  # (the heights the map took: under load a node skips a backlog rather than burst it)
        order = [(t, z) for t, z in sorted(heights) if t in used]
    tau = 0.080
    y: float | None = None
    previous = 0.0
    checked = 0
    for t, z in order:  # the documented formula, written out again: 200·10^x, one-pole of τ = 80 ms
        x = min(1.0, max(0.0, (z - low) / (high - low)))
        target = 200.0 * 10.0 ** x
        y = target if y is None else y + (1.0 - math.exp(-(t - previous) / tau)) * (target - y)
        previous = t
        if t in by_t:  # (and what reached the receiver: the OSC sink may skip a backlog too)
            assert math.isclose(by_t[t], y, rel_tol=1e-6), (t, by_t[t], y)  # (float32 on the wire)
            checked += 1
    assert checked >= 100 and checked >= 0.9 * len(order), (checked, len(order), len(heights))
    assert len({round(v) for v in by_t.values()}) > 20  # the hand really moved the cutoff
    assert all(200.0 <= v <= 2000.0 for v in by_t.values())


@pytest.mark.external
def test_pure_data_routes_sound_cutoff_as_the_docs_show(net, owner, spawn, tmp_path):
    """docs/mapping.md's Pd chain, in headless Pd: ``[route sound]`` → ``[route cutoff]`` with a
    target's ``derived_address = "/{robot}/{name}"``, and the default address beside it."""
    fake = owner("pepper", model_info("pepper"))
    start(net, robots="pepper", features=("hand",))
    node = map_node(net, cutoff_example())
    short, default = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    patch = Patch()
    routed = patch.chain(osc_input(patch, short), patch.obj("route", "sound"), patch.obj("route", "cutoff"))
    patch.connect(routed, 0, patch.obj("print", "CUTOFF"))
    whole = patch.chain(osc_input(patch, default), patch.obj("route", "sound"), patch.obj("route", "derived"),
                        patch.obj("route", "map"), patch.obj("route", "cutoff"))
    patch.connect(whole, 0, patch.obj("print", "DEFAULT"))
    pd = start_pd(spawn, tmp_path, patch)
    net.start(OscSink(OscSinkConfig(subscribe=("sound/derived/**",), targets=(
        f"127.0.0.1:{default}", {"to": f"127.0.0.1:{short}", "derived_address": "/{robot}/{name}"})), name="pd"))
    sweep(fake, until=lambda: len(printed(pd, "CUTOFF")) >= 20 and len(printed(pd, "DEFAULT")) >= 20)
    assert not errors(pd), errors(pd)
    values = [float(v) for v in printed(pd, "CUTOFF")]
    assert all(200 <= v <= 2000 for v in values) and len(set(values)) > 5, values
    assert node.chains["cutoff"].spec.unit == "Hz"
