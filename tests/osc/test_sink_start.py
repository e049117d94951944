"""Stale samples (issue 13, item 6): starting an installation on one host drops
nothing as stale and warns of nothing, while a sample that really is old is still
dropped, counted and warned about.

What made every start warn: a ``features`` node worked out a robot's reach boxes
(~0.1 s) on its worker, so the frames queued meanwhile came out as derived values
already older than the sinks' ``max_age_ms``. It now does that on a thread of its
own and skips the frames that come meanwhile."""

from __future__ import annotations

import logging
import time

import pytest

from sonibus.adapters.features import Features, FeaturesConfig, catalog
from sonibus.adapters.osc import OscSink, OscSinkConfig

from ..conftest import wait_for
from .test_sink_delivery import handshake, keyed, messages, sample


def stale_warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING and "older than" in r.getMessage()]


@pytest.mark.realtime
def test_starting_robots_features_and_a_sink_drops_nothing_as_stale(net, receivers, caplog):
    """As ``sonibus run`` starts a file holding two robots, a features node and a sink, in that
    order, in one process (one Zenoh session). Before, the derived values of the frames queued
    while the features node learned the robots reached the sink 60..170 ms late; now ~5..40 ms."""
    caplog.set_level(logging.WARNING)
    plain = receivers()
    host = net.bus("host")
    for robot in ("pepper", "nao"):
        net.sim(robot, bus=host, rate_hz=50)
    features = net.start(Features(FeaturesConfig(robots=("pepper", "nao")), name="features"), host)
    # (a light load: a sink that cannot keep up on a busy machine drops what really is stale)
    sink = net.start(OscSink(OscSinkConfig(subscribe=("*/joints/HeadYaw", "*/derived/qom/*"), targets=(plain.target,)),
                             name="sound"), host)
    wait_for(lambda: min(len(messages(plain, f"/{r}/derived/qom/Body")) for r in ("pepper", "nao")) >= 25,
             timeout=10, what="the derived values of 25 frames of each robot",
             explain=lambda: f"features {features.stats}\nsink {sink.stats}")
    assert stale_warnings(caplog) == []
    assert sink.stats["stale"] == 0
    assert features.stats["waiting_info"] >= 1  # (frames came while it learned the robot: skipped, not late)


def test_a_robot_learnt_slowly_makes_nothing_stale(net, receivers, caplog, monkeypatch):
    """On a busy machine working out a robot's features can take longer than ``max_age_ms``
    (1.5 s here, against 1 s: a busy CI machine delays a frame by 0.4 s now and then, which
    is not what this is about): the frames that come meanwhile are skipped as
    ``waiting_info``, never computed late, so neither the features node nor the sink drops
    anything as stale."""
    caplog.set_level(logging.WARNING)
    derived = catalog.derived

    def slowly(*args, **kwargs):
        time.sleep(1.5)  # (the slow machine, not a wait on a condition)
        return derived(*args, **kwargs)

    monkeypatch.setattr(catalog, "derived", slowly)
    plain = receivers()
    host = net.bus("host")
    net.sim("pepper", bus=host, rate_hz=50)
    features = net.start(Features(FeaturesConfig(robots="pepper", max_age_ms=1000), name="features"), host)
    sink = net.start(OscSink(OscSinkConfig(subscribe="pepper/derived/qom/*", targets=(plain.target,),
                                           max_age_ms=1000), name="sound"), host)
    wait_for(lambda: len(messages(plain, "/pepper/derived/qom/Body")) >= 25, timeout=10,
             what="the derived values of 25 frames", explain=lambda: f"features {features.stats}\nsink {sink.stats}")
    assert stale_warnings(caplog) == []
    assert features.stats["stale"] == sink.stats["stale"] == 0
    assert features.stats["waiting_info"] >= 30  # the frames of the 1.5 s it took: skipped


def test_a_really_old_sample_is_dropped_counted_and_warned_about(net, receivers, caplog):
    caplog.set_level(logging.WARNING)
    raw = receivers()
    sink = net.start(OscSink(keyed("toy/joints/*", targets=(raw.target,)), name="sound"))
    src = net.bus("toy")
    handshake(src, "toy/joints/Hello", raw)
    src.put("toy/joints/Old", sample(1, 0.5, t=time.time() - 0.3))
    src.put("toy/joints/Fresh", sample(2, 0.25))
    wait_for(lambda: ("/toy/joints/Fresh", [0.25]) in messages(raw), what="the fresh sample")
    assert [a for a, _ in messages(raw) if a != "/toy/joints/Hello"] == ["/toy/joints/Fresh"]
    assert sink.stats["stale"] == 1
    [warning] = stale_warnings(caplog)
    assert "'toy/joints/Old'" in warning and "max_age_ms = 100" in warning
