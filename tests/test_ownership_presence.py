"""Silence explained (issue 14, item 3), on loopback: a sink warns once when a robot
is on the bus and its owner up but none of its frames arrives; not while the owner
is still connecting to its robot (no ``<robot>/info`` yet), not for a robot that
streams. (With a real access control refusing the frames: tests/net/test_silence.py.)"""

from __future__ import annotations

import logging
import time

import pytest

from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.osc import sink as osc_sink
from sonibus.bus import codec, keys, presence
from sonibus.bus.ownership import Claim

from .conftest import wait_for
from .osc.pd import Datagrams

SILENCE = "is on the bus but none of its data arrived"


@pytest.fixture
def quick(monkeypatch):
    monkeypatch.setattr(presence, "SILENCE_S", 0.5)
    # (the sink tells presence of a robot's data at most every HEARD_EVERY_S, 0.5 s: a silence as short must
    # be longer than that, or a streaming robot is silent at the instant presence wakes for it, SILENCE_S on)
    monkeypatch.setattr(osc_sink, "HEARD_EVERY_S", 0.1)


@pytest.fixture
def receiver():
    datagrams = Datagrams()
    yield datagrams
    datagrams.close()


def warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if SILENCE in r.getMessage()]


def test_silence_is_told_once_the_owner_is_up_and_not_before(net, quick, receiver, caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")
    net.start(OscSink(OscSinkConfig(subscribe=("nao/joints/*",), targets=(receiver.target,)), name="sound"))
    owner = net.bus("nao-owner")
    token = owner.token(Claim("nao", int(time.time() * 1000), owner.host, "nao-owner").key)  # noqa: F841 (held)
    time.sleep(1.5)  # three times the silence, with the owner still connecting (no info)
    assert warnings(caplog) == []
    info = {"robot": "nao", "model": "nao", "joints": [], "rate_hz": 50}
    served = owner.serve(keys.info("nao"), lambda q: q.reply(q.key_expr, codec.encode(info),  # noqa: F841
                                                             encoding=codec.ENCODING))
    [line] = wait_for(lambda: warnings(caplog), what="the silence warning")
    assert "sound: robot 'nao'" in line and "per_joint_keys" in line
    time.sleep(1.0)
    assert len(warnings(caplog)) == 1, "warned more than once"


def test_a_robot_that_streams_is_not_silent(net, quick, receiver, caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")
    net.start(OscSink(OscSinkConfig(subscribe=("pepper/joints/*",), targets=(receiver.target,)), name="sound"))
    net.sim("pepper", rate_hz=20)
    wait_for(lambda: receiver.data(), what="data at the receiver")
    time.sleep(1.5)
    assert warnings(caplog) == []


def test_a_silent_robot_whose_data_then_arrives_is_told_so_once(net, quick, receiver, caplog):
    """README: the warning "comes once, and `its data arrives now` follows when it does"."""
    caplog.set_level(logging.WARNING, logger="sonibus")
    net.start(OscSink(OscSinkConfig(subscribe=("nao/joints/*",), targets=(receiver.target,)), name="sound"))
    owner = net.bus("nao-owner")
    token = owner.token(Claim("nao", int(time.time() * 1000), owner.host, "nao-owner").key)  # noqa: F841 (held)
    info = {"robot": "nao", "model": "nao", "joints": [], "rate_hz": 50}
    served = owner.serve(keys.info("nao"), lambda q: q.reply(q.key_expr, codec.encode(info),  # noqa: F841
                                                             encoding=codec.ENCODING))
    wait_for(lambda: warnings(caplog), what="the silence warning")
    arrives = "sound: robot 'nao': its data arrives now"
    for seq in range(5):
        owner.put(keys.frame("nao"), {"t": time.time(), "seq": seq, "names": ["HeadYaw"], "v": [0.1]})
        time.sleep(0.05)
    wait_for(lambda: arrives in caplog.text, what="'its data arrives now'")
    wait_for(lambda: receiver.data(), what="the joint at the receiver")
    assert caplog.text.count(arrives) == 1
    assert len(warnings(caplog)) == 1
