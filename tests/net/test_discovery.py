"""Issue 14, item 1: one-shot commands wait for discovery. On a LAN of peers found by
multicast, `sonibus nodes` used to return after about 0.2 s and list no robot in 6 of
8 tries; it now waits (bounded) until its links are up, every time."""

from __future__ import annotations

import time

import pytest

from .test_multihost import SIM, robots_listed, show, started

pytestmark = pytest.mark.external

TRIES = 5


def test_nodes_in_peer_mode_finds_the_robot_every_time(topology, tmp_path, figure):
    robot, other = topology.lan("robot", "other")
    path = show(tmp_path, f"""
        [bus]
        mode = "peer"
        [nodes.robot]
        robot = "pepper"
        {SIM}
        """)
    started(topology, robot.sonibus("run", path))
    took = []
    for _ in range(TRIES):
        begun = time.monotonic()
        assert robots_listed(other.cli("nodes")) == 1
        took.append(time.monotonic() - begun)
    figure(f"sonibus nodes, {TRIES} tries, longest", max(took), "s")
    sent = other.cli("send", "pepper", "stop")
    assert sent.returncode == 0, sent.stderr
