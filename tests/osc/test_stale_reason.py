"""A stale-sample warning names the likely cause for where the robot's node runs
(issue 29, item 12): on one busy machine it said "a stalled publisher or link, or
clocks not in step" at the start of nearly every run and through a ×2 replay,
sending a newcomer after clocks that were one and the same."""

from __future__ import annotations

import logging
import time

import pytest

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.bus import Bus, encode, framing
from sonibus.bus.claimwatch import owners

from ..conftest import wait_for
from .test_sink_delivery import messages as received
from .test_sink_start import stale_warnings


@pytest.mark.parametrize(("robot_host", "cause"), [
    (None, "pepper's node (sim-pepper) runs on this machine too, so no clock is to blame: this machine was too "
           "busy to run both in time (its CPU), or a node paused"),
    ("robot-laptop", "pepper's node runs on robot-laptop: a link or node that stalled, or the clocks of "
                     "robot-laptop and {here} not in step (NTP: 'chronyc tracking' on both)"),
], ids=["same machine", "another machine"])
def test_a_stale_warning_names_the_likely_cause_for_where_the_robot_runs(net, receivers, caplog, robot_host, cause):
    caplog.set_level(logging.WARNING)
    raw = receivers()
    sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/joints/HeadYaw", targets=(raw.target,)), name="sound"))
    owner = net.bus("robot")
    net.sim("pepper", bus=Bus(owner.session, "robot", host=robot_host) if robot_host else owner, rate_hz=20)
    wait_for(lambda: owners(sink.bus).owner("pepper"), what="the sink to know pepper's owner")
    wait_for(lambda: received(raw, "/pepper/joints/HeadYaw"), what="pepper's frames through the sink")
    script = net.bus("script")
    publisher = script.stream_publisher("pepper/frame")
    old = encode(framing.frame(time.time() - 0.5, 1, ["HeadYaw"], [0.1]))  # half a second old
    [warning] = wait_for(lambda: publisher.put(old) or stale_warnings(caplog), what="an old frame dropped, warned of")
    assert warning.partition("ms old: ")[2].startswith(cause.format(here=sink.bus.host)), warning
    assert "'pepper/frame'" in warning

