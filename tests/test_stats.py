"""Node health on the bus: every node's counters, thread-safe, published once a
second on ``sonibus/stats/<host>/<node>`` (schema ``node_stats``) and read back
with ``sonibus.bus.health``."""

from __future__ import annotations

import itertools
import logging
import math
import socket
import sys
import threading
import time
from collections import defaultdict
from typing import Any

import pytest

from sonibus import schemas
from sonibus.adapters.naoqi import NaoqiConfig, NaoqiRobot
from sonibus.adapters.osc import OscSink, OscSinkConfig
from sonibus.adapters.sim.naoqi import FakeNaoqi, FakeNaoqiConfig
from sonibus.bus import Adapter, decode, health, keys
from sonibus.bus.queue import SampleQueue
from sonibus.bus.stats import BASE, RESERVOIR, Counters, Latencies
from sonibus.bus.streams import Streams

from .conftest import free_port, wait_for


class Collected:
    """Every stats message on the bus, by node, as it arrives."""

    def __init__(self, bus: Any) -> None:
        self.by_node: dict[str, list[dict[str, Any]]] = defaultdict(list)
        self._subscriber, self._queue = bus.subscribe(keys.NODE_STATS)

    def of(self, node: str) -> list[dict[str, Any]]:
        for key, payload in self._queue.drain(timeout=0):
            message = decode(payload)
            assert key == keys.node_stats(message["host"], message["node"])
            self.by_node[message["node"]].append(message)
        return self.by_node[node]


def check_series(messages: list[dict[str, Any]], kind: str) -> None:
    """Each message fits the schema; about one a second; counters never go back."""
    for message in messages:
        schemas.validate("node_stats", message)
        assert message["adapter"] == kind and message["state"] == "running"
        assert set(BASE) <= set(message["counters"])
    for before, after in itertools.pairwise(messages):
        assert after["t"] - before["t"] >= 0.5, (before["t"], after["t"])
        assert after["uptime_s"] > before["uptime_s"]
        for name, count in before["counters"].items():
            assert after["counters"][name] >= count, name


def test_the_stats_key_carries_a_running_sink_and_robot_about_once_a_second(net):
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(5.0)
    try:
        watcher = net.bus("watcher")
        collected = Collected(watcher)
        target = f"127.0.0.1:{receiver.getsockname()[1]}"
        net.start(OscSink(OscSinkConfig(targets=(target,)), name="sound"))
        net.sim("pepper", rate_hz=50)
        wait_for(lambda: len(collected.of("sound")) >= 3 and len(collected.of("sim-pepper")) >= 3, timeout=10,
                 what="three stats messages from each node",
                 explain=lambda: f"{ {n: len(m) for n, m in collected.by_node.items()} }")
        assert receiver.recv(65536).startswith(b"/pepper/")  # the data really went out over UDP

        sound, robot = collected.of("sound"), collected.of("sim-pepper")
        check_series(sound, "osc")  # the registered names (issue 19, item 5)
        check_series(robot, "sim")
        assert sound[-1]["counters"]["received"] > sound[0]["counters"]["received"] > 0
        assert sound[-1]["counters"]["sent"] > sound[0]["counters"]["sent"] > 0
        assert sound[-1]["rates"]["received"] > 0 and sound[-1]["rates"]["sent"] > 0
        assert sound[-1]["counters"]["bad"] == 0
        assert robot[-1]["counters"]["sent"] > robot[0]["counters"]["sent"] > 0  # frames published
        assert robot[-1]["rates"]["sent"] > 0
        for message in (sound[-1], robot[-1]):
            latency = message["latency_ms"]
            assert 0 <= latency["p50"] <= latency["p99"] and latency["samples"] >= 1
            assert message["process"]["rss_bytes"] > 10e6 and message["process"]["cpu_percent"] >= 0
        assert list(sound[-1]["metrics"]["sent_to"]) == [target] and sound[-1]["metrics"]["sent_to"][target] > 0
        assert "frames_skipped" in robot[-1]["metrics"]

        found = health.latest(watcher, timeout=2.0)  # served at once, the same messages
        assert {(watcher.host, "sound"), (watcher.host, "sim-pepper")} <= set(found)
        latest = found[(watcher.host, "sound")]
        schemas.validate("node_stats", latest)
        assert latest["counters"]["sent"] >= sound[-1]["counters"]["sent"]
        line = health.summary(latest)
        assert line.startswith("rx ") and " tx " in line and "drop 0 bad 0 p99 " in line and " MB" in line
    finally:
        receiver.close()


def test_a_node_serves_its_stats_before_its_first_second(net):
    quiet = net.start(Adapter(name="quiet"))
    quiet.count("received", 3)
    asker = net.bus("asker")
    found = health.latest(asker, timeout=2.0)
    stats = found[(asker.host, "quiet")]
    schemas.validate("node_stats", stats)
    assert stats["counters"] == {**dict.fromkeys(BASE, 0), "received": 3}
    assert "latency_ms" not in stats and "metrics" not in stats


@pytest.mark.parametrize("per_joint_keys", [False, True])
def test_a_sink_subscribed_to_everything_leaves_the_stats_out(net, per_joint_keys):
    watcher = net.bus("watcher")
    collected = Collected(watcher)
    everything = net.start(OscSink(OscSinkConfig(subscribe="**", targets=(f"127.0.0.1:{free_port()}",),
                                                 per_joint_keys=per_joint_keys), name="everything"))
    net.start(Adapter(name="other"))
    wait_for(lambda: len(collected.of("other")) >= 2 and len(collected.of("everything")) >= 2, timeout=10,
             what="stats of both nodes on the bus")
    assert everything.stats["bad"] == 0 and everything.stats["received"] == 0  # not robot data


def test_a_subscription_that_names_the_stats_gets_them(net):
    """Left out of broad patterns, taken when asked for by name (a monitor of your own)."""
    queue = SampleQueue(100)
    streams = Streams(net.bus("monitor"), ["sonibus/stats/**"], queue)
    try:
        net.start(Adapter(name="other"))
        key, payload = wait_for(lambda: queue.get(0.1), timeout=10, what="a node's stats")
        stats = streams.incoming(key, payload).event
        schemas.validate("node_stats", stats)
        assert key == keys.node_stats(stats["host"], stats["node"])
    finally:
        streams.undeclare()


def test_counters_are_exact_when_counted_from_many_threads():
    counters = Counters(["sent"])
    threads, per_thread = 8, 20_000
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads switch as often as they can: a lost update would show
    try:
        start = threading.Barrier(threads + 1)

        def work(i: int) -> None:
            start.wait()
            for _ in range(per_thread):
                counters.add("sent")
                counters.add(f"own{i % 2}", 2)

        workers = [threading.Thread(target=work, args=(i,)) for i in range(threads)]
        for worker in workers:
            worker.start()
        start.wait()
        seen = []
        while any(w.is_alive() for w in workers):  # reading meanwhile is safe, and never goes back
            seen.append(counters["sent"])
            dict(counters)
        for worker in workers:
            worker.join()
    finally:
        sys.setswitchinterval(interval)
    assert seen == sorted(seen)
    assert dict(counters) == {"sent": threads * per_thread, "own0": threads * per_thread, "own1": threads * per_thread}


def test_a_tally_counted_under_its_owners_lock_reads_with_the_counters():
    counters = Counters(["sent", "bad"])
    counters.add("sent", 2)
    tally = counters.tally(["sent", "received"])
    owner = threading.Lock()  # (what the tally relies on: one writer at a time)
    threads, per_thread = 4, 5_000

    def work() -> None:
        for _ in range(per_thread):
            with owner:
                tally["sent"] += 3
                tally["received"] += 1

    workers = [threading.Thread(target=work) for _ in range(threads)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    assert dict(counters) == {"sent": 2 + 3 * threads * per_thread, "bad": 0, "received": threads * per_thread}


def test_the_latencies_kept_are_a_uniform_sample_of_every_one_seen():
    """Each second keeps RESERVOIR latencies of however many were seen, each with the same
    chance: over many seconds of 0..9,999 ms (in s), every tenth of the range is kept as often."""
    latencies, tenths, seconds, seen = Latencies(), [0] * 10, 100, 10_000
    for _ in range(seconds):
        for ms in range(seen):
            latencies.add(ms / 1000)
        for kept in latencies._kept:  # (the sample itself: take() gives its p50 and p99)
            tenths[int(kept)] += 1
        assert latencies.take()["samples"] == seen
    expected = seconds * RESERVOIR / 10  # 2,560 each; the standard deviation is about 48
    assert all(abs(n - expected) < 0.1 * expected for n in tenths), tenths


def test_an_adapter_counts_through_count_and_reads_like_a_dict():
    class Probe(Adapter):
        counters = ("written",)

    probe = Probe(name="probe")
    assert dict(probe.stats) == {**dict.fromkeys(BASE, 0), "written": 0}  # declared: zeros show
    probe.count("written", 2)
    probe.count("other")
    assert probe.stats["written"] == 2 and probe.stats.get("other") == 1 and probe.stats.get("missing", 0) == 0
    assert probe.stats == {"written": 2, "other": 1}  # zeros are as good as absent, as in collections.Counter
    assert probe.stats != {"written": 2}


def test_dropped_counts_the_drops_of_every_queue_the_node_owns():
    node = Adapter(name="queues")
    first, second = node.own(SampleQueue(1)), node.own(SampleQueue(2))
    for item in range(4):
        first.put(item)
        second.put(item)
    node.own(SampleQueue(1)).put(0)  # full, not overfull
    assert node.stats["dropped"] == 3 + 2 == first.dropped + second.dropped


def test_a_metrics_hook_that_raises_misses_a_second_and_the_node_goes_on(net, caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")

    class Flaky(Adapter):
        calls = 0

        def metrics(self) -> dict[str, Any]:
            self.calls += 1
            if self.calls == 1:
                raise RuntimeError("not ready")
            return {"calls": self.calls}

    watcher = net.bus("watcher")
    collected = Collected(watcher)
    flaky = net.start(Flaky(name="flaky"))
    wait_for(lambda: collected.of("flaky"), timeout=10, what="stats after the failed second")
    (first, *_) = collected.of("flaky")
    assert first["metrics"]["calls"] >= 2 and flaky.state == "running" and flaky.stats["errors"] == 0
    assert "flaky: stats not sent: RuntimeError: not ready" in caplog.text  # not silent


def test_a_failed_node_says_so_in_its_stats(net):
    class Dying(Adapter):
        def _start(self) -> None:
            self.spawn(self._die, "work")

        def _die(self) -> None:
            raise RuntimeError("gone")

    watcher = net.bus("watcher")
    collected = Collected(watcher)
    dying = net.start(Dying(name="dying"))
    wait_for(lambda: collected.of("dying"), timeout=10, what="the failed node's stats")
    stats = collected.of("dying")[0]
    schemas.validate("node_stats", stats)
    assert dying.state == stats["state"] == "failed" and stats["counters"]["errors"] == 1


def test_naoqi_robot_counts_warns_and_publishes_its_stats(net, caplog):
    fake = FakeNaoqi(FakeNaoqiConfig(listen=f"tcp://127.0.0.1:{free_port()}", rate_hz=100)).start()
    robot = None
    try:
        watcher = net.bus("watcher")
        collected = Collected(watcher)
        robot = net.start(NaoqiRobot(NaoqiConfig(robot="pepper", url=fake.url, rate_hz=50, retry_max_s=0.5,
                                                 connect_timeout_s=2.0), name="naoqi-pepper"))
        wait_for(lambda: robot.stats["sent"] >= 10, timeout=15, what="frames from the NAOqi robot")
        names = robot.model.joint_names
        with caplog.at_level(logging.WARNING, logger="sonibus.bus.adapter"):
            robot.publish_frame(time.time(), 10**9, [math.nan, *[0.0] * (len(names) - 1)], names)
        assert robot.stats["joints_left_out"] == 1
        assert f"{names[0]} left out of frame {10**9}" in caplog.text and "joints_left_out 1" in caplog.text

        wait_for(lambda: len(collected.of("naoqi-pepper")) >= 2, timeout=10, what="the robot's stats")
        stats = collected.of("naoqi-pepper")[-1]
        check_series(collected.of("naoqi-pepper"), "naoqi")
        assert stats["counters"]["sent"] > 0 and stats["latency_ms"]["samples"] >= 1
        assert stats["metrics"]["rate_hz"] >= 0 and "read_ms" in stats["metrics"]
    finally:
        if robot is not None:
            robot.stop()  # before its fake
        fake.stop()


@pytest.mark.parametrize("stats, line", [
    ({}, "rx 0/s tx 0/s drop 0 bad 0"),
    ({"rates": {"received": 0.4}, "counters": {"dropped": 1234, "bad": 5, "errors": 2},
      "process": {"cpu_percent": 101.6, "rss_bytes": 1.5e9}},
     "rx 0/s tx 0/s drop 1,234 bad 5 err 2 cpu 102% 1500 MB"),
])
def test_summary_is_one_line(stats, line):
    assert health.summary(stats) == line


def test_latencies_added_from_two_threads_while_a_third_takes_are_each_counted_once():
    """``add`` takes no lock (a deque, folded every ``FOLD``): however the threads interleave,
    the intervals' ``samples`` add up to every latency added, and no sample holds more than
    its size nor a latency that was not added."""
    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # (threads switch as often as they can: the races, if any, happen)
    latencies, per_thread, taken = Latencies(size=16), 50_000, []
    stop = threading.Event()

    def adder(offset: float) -> None:
        for i in range(per_thread):
            latencies.add(offset + i * 1e-9)

    def taker() -> None:
        while not stop.is_set():
            taken.append(latencies.take())

    try:
        threads = [threading.Thread(target=adder, args=(offset,)) for offset in (1.0, 2.0)]
        watcher = threading.Thread(target=taker)
        for thread in (*threads, watcher):
            thread.start()
        for thread in threads:
            thread.join()
        stop.set()
        watcher.join()
    finally:
        sys.setswitchinterval(switch)
    taken.append(latencies.take())
    counted = [t for t in taken if t is not None]
    assert sum(t["samples"] for t in counted) == 2 * per_thread
    assert len(counted) > 1  # (the taker did take while they added)
    assert all(1000.0 <= t["p50"] <= 2000.0 + per_thread * 1e-6 for t in counted)
