"""``sonibus run`` under a supervisor: READY once its nodes run, WATCHDOG only while every
node is healthy (not failed, not hung), STOPPING at the end — told over $NOTIFY_SOCKET,
here a real unix datagram socket read as systemd reads it."""

from __future__ import annotations

import os
import signal
import threading

import pytest

import sonibus.bus.adapter as adapter_module
from sonibus.bus import Adapter, runner
from sonibus.bus.busconfig import BusConfig
from sonibus.bus.errors import NodeFailed
from sonibus.bus.notify import Notifier
from sonibus.bus.queue import SampleQueue
from sonibus.bus.watchdog import Watchdog

from .conftest import SONIBUS, free_port, wait_for
from .supervisor import Supervisor
from .wakes import calls


def test_sonibus_run_says_ready_pings_the_watchdog_and_says_stopping(supervisor, spawn, tmp_path):
    show = tmp_path / "show.toml"
    show.write_text('[bus]\nmulticast = false\nlisten = ["tcp/127.0.0.1:0"]\n\n'
                    '[nodes.pepper]\nadapter = "sim"\nrate_hz = 20\n')
    env = {**os.environ, **supervisor.environ(watchdog_s=0.6)}
    env.pop("WATCHDOG_PID")  # (a child cannot know its pid beforehand; systemd sets it only for a forking main)
    run = spawn(SONIBUS, "run", str(show), env=env)
    ready = wait_for(lambda: supervisor.with_key("READY"), 20, "READY=1", lambda: str(supervisor.messages))
    assert ready[0]["STATUS"].startswith("running pepper on "), ready
    assert any(s.startswith("joining the bus (peer") for s in supervisor.statuses()), supervisor.statuses()
    assert "starting node 'pepper' (sim)" in supervisor.statuses()
    assert supervisor.with_key("EXTEND_TIMEOUT_USEC")[0] == {"EXTEND_TIMEOUT_USEC": "10000000"}  # joining: no hurry
    wait_for(lambda: len(supervisor.after(lambda m: "READY" in m)) > 4, 10, "watchdog pings after READY")
    assert all(m == {"WATCHDOG": "1"} for m in supervisor.after(lambda m: "READY" in m)[1:4])
    code, _, err = run.stop(signal.SIGTERM)
    assert code == 130, err
    (stopping,) = supervisor.with_key("STOPPING")
    assert stopping == {"STOPPING": "1", "STATUS": "stopping: stopped"}
    assert "WATCHDOG" not in supervisor.messages[-1][1]


class Worker(Adapter):
    """A node whose worker takes items from its queue: "hang" blocks it until ``release``,
    "fail" makes it raise; its ``metrics()`` blocks while ``stats_hang`` is set."""

    def _start(self) -> None:
        self.queue = self.own(SampleQueue(16))
        self.release = threading.Event()
        self.stats_hang = threading.Event()
        self.spawn(self._work, "work")

    def _work(self) -> None:
        while not self.stopping.is_set():
            item = self.queue.get(timeout=0.1)
            if item == "hang":
                while not (self.release.is_set() or self.stopping.is_set()):
                    self.release.wait(0.1)  # (a call that does not return)
            elif item == "fail":
                raise RuntimeError("the device went away")

    def metrics(self) -> dict:
        while self.stats_hang.is_set() and not self.stopping.is_set():
            self.release.wait(0.05)
        return {}


class Running:
    """``runner.run`` of ``nodes`` on a thread, told to ``supervisor`` (a watchdog of ``watchdog_s``)."""

    def __init__(self, supervisor: Supervisor, nodes: list[Adapter], watchdog_s: float = 0.3) -> None:
        self.stop, self.error = threading.Event(), None
        watchdog = Watchdog(Notifier(supervisor.environ(watchdog_s)), nodes)
        cfg = BusConfig(multicast=False, listen=(f"tcp/127.0.0.1:{free_port()}",))
        self.thread = threading.Thread(target=self._run, args=(nodes, cfg, watchdog), daemon=True)
        self.thread.start()

    def _run(self, nodes: list[Adapter], cfg: BusConfig, watchdog: Watchdog) -> None:
        try:
            runner.run(nodes, cfg, self.stop, watchdog=watchdog)
        except Exception as exc:
            self.error = exc

    def end(self) -> None:
        self.stop.set()
        self.thread.join(10)
        assert not self.thread.is_alive()


@pytest.fixture
def quick(monkeypatch):
    """Stats every 0.1 s and a worker hung after 1 s: what takes minutes in a show takes seconds."""
    monkeypatch.setattr(adapter_module, "STATS_EVERY_S", 0.1)
    monkeypatch.setattr(adapter_module, "HANG_S", 1.0)


@pytest.mark.parametrize("how", ["worker", "stats"])
def test_the_watchdog_is_not_fed_while_a_node_hangs_and_is_again_once_it_goes_on(supervisor, quick, how):
    worker, other = Worker(name="worker"), Worker(name="other")
    running = Running(supervisor, [other, worker])
    try:
        wait_for(lambda: len(supervisor.with_key("WATCHDOG")) >= 3, 20, "pings while healthy")
        if how == "worker":
            worker.queue.put("hang")
            worker.queue.put("next")  # waits: nobody takes it
        else:
            worker.stats_hang.set()
        unhealthy = wait_for(lambda: [s for s in supervisor.statuses() if s.startswith("unhealthy")], 10,
                             "an unhealthy status", lambda: str(supervisor.messages[-5:]))
        expected = {"worker": "unhealthy: node 'worker' hung: a worker has taken nothing from its queue for ",
                    "stats": "unhealthy: node 'worker' hung: its stats worker has not gone round for "}[how]
        assert unhealthy[0].startswith(expected), unhealthy
        wait_for(lambda: len(supervisor.after(lambda m: m.get("STATUS", "").startswith("unhealthy"))) >= 4, 10,
                 "the next checks")
        while_hung = supervisor.after(lambda m: m.get("STATUS", "").startswith("unhealthy"))
        assert all("WATCHDOG" not in m for m in while_hung), while_hung  # systemd would kill it now

        worker.stats_hang.clear()
        worker.release.set()
        again = wait_for(lambda: supervisor.after(lambda m: "WATCHDOG" in m and "STATUS" in m), 10, "a ping again")
        assert again[0]["STATUS"].startswith("running other, worker on "), again
    finally:
        running.end()
    assert running.error is None


def test_a_failed_node_stops_the_pings_and_ends_the_run_with_its_reason(supervisor, quick):
    worker = Worker(name="worker")
    running = Running(supervisor, [worker])
    try:
        wait_for(lambda: len(supervisor.with_key("WATCHDOG")) >= 2, 20, "pings while healthy")
        worker.queue.put("fail")
        wait_for(lambda: not running.thread.is_alive(), 10, "the run to end")
    finally:
        running.end()
    assert isinstance(running.error, NodeFailed)
    assert str(running.error) == "node 'worker': worker 'work' failed: RuntimeError: the device went away"
    after = supervisor.after(lambda m: "STOPPING" in m)
    assert after == [{"STOPPING": "1", "STATUS": f"stopping: {running.error}"}], after  # the last word, no ping


def test_notify_socket_in_the_abstract_namespace_and_a_watchdog_meant_for_another_process():
    name = f"@sonibus-test-{os.getpid()}-{free_port()}"
    listening = Supervisor(name)
    try:
        notifier = Notifier({"NOTIFY_SOCKET": name, "WATCHDOG_USEC": "5000000", "WATCHDOG_PID": "1"})
        assert notifier.watchdog_s is None  # systemd meant pid 1's watchdog, not ours
        assert notifier.send(STATUS="two\nlines")  # a value is one line: the protocol is KEY=VALUE lines
        wait_for(lambda: listening.messages, what="the datagram")
        assert listening.messages[0][1] == {"STATUS": "two lines"}
        assert Notifier({"NOTIFY_SOCKET": name, "WATCHDOG_USEC": "5000000"}).watchdog_s == 5.0
    finally:
        listening.close()


def test_a_supervisor_that_went_away_is_logged_once_and_nothing_raises(tmp_path, caplog):
    notifier = Notifier({"NOTIFY_SOCKET": str(tmp_path / "gone")})
    assert not notifier.send(READY=1) and not notifier.send(WATCHDOG=1)
    assert [r.getMessage() for r in caplog.records] == [
        f"cannot notify the supervisor at NOTIFY_SOCKET={tmp_path / 'gone'}: [Errno 2] No such file or directory"]


def test_the_run_sleeps_between_its_checks_and_a_failing_node_still_ends_it_at_once(supervisor):
    """``run``'s thread wakes for the watchdog's and the trimmer's checks (once a second), a stop,
    or a node that fails (which sets ``stop``), not ten times a second to look (issue 35)."""
    worker = Worker(name="worker")
    running = Running(supervisor, [worker], watchdog_s=30)  # (its checks every 10 s; the trimmer's every 1 s)
    try:
        wait_for(lambda: supervisor.with_key("READY"), 20, "READY=1")
        # its waits counted where it waits (a thread's context switches count its GIL waits too: CI saw 12)
        counted = calls({"run": (running.stop, "wait")}, 2.0)
        assert 1 <= counted["run"] <= 3, counted  # (2 checks in 2 s; before, 20)
        worker.queue.put("fail")
        wait_for(lambda: not running.thread.is_alive(), 10, "the run to end")
    finally:
        running.end()
    assert isinstance(running.error, NodeFailed)
