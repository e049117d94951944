"""A worker that dies is never silent: the node's state, a ``node`` event, and
``sonibus run`` ending with an error — unless the worker may restart."""

from __future__ import annotations

import io
import threading
from dataclasses import dataclass

import msgpack
import pytest
from sonibus_testplugin import JsonLinesConfig, JsonLinesSink

from sonibus.bus import Adapter, decode, keys
from sonibus.bus.cli import Environment, main
from sonibus.bus.queue import SampleQueue
from sonibus.bus.streams import Streams

from .conftest import SONIBUS, wait_for


def test_a_dying_worker_fails_its_node_with_an_event_and_its_state(net, tmp_path):
    """The third-party jsonl sink does not check payloads: garbage kills its worker."""
    events = []
    watcher = net.bus("watcher")
    watcher.session.declare_subscriber(keys.NODE_EVENTS, lambda s: events.append(decode(s.payload.to_bytes())))
    sink = net.start(JsonLinesSink(JsonLinesConfig(path=str(tmp_path / "lines.jsonl")), name="lines"))
    script = net.bus("script").session.declare_publisher("pepper/joints/HeadYaw")
    wait_for(lambda: script.matching_status.matching, what="the sink's subscription")
    script.put(b"\xc1 not msgpack")

    wait_for(lambda: sink.state == "failed", what="the node to fail")
    assert sink.failure.startswith("worker 'write' failed: DecodeError: payload is not msgpack"), sink.failure
    wait_for(lambda: events, what="the node event")
    assert events[0] | {"t": 0} == {"t": 0, "kind": "node", "host": watcher.host, "node": "lines",
                                    "adapter": "jsonl", "state": "failed", "error": sink.failure}
    (described,) = watcher.query(keys.node_token(watcher.host, "lines"))
    assert described["state"] == "failed" and described["failure"] == sink.failure


def test_sonibus_run_ends_with_an_error_when_a_node_fails(net, spawn, tmp_path):
    show = tmp_path / "show.toml"
    show.write_text(f'[bus]\nmulticast = false\nconnect = ["{net.endpoint}"]\n\n'
                    f'[nodes.lines]\nadapter = "jsonl"\npath = "{tmp_path / "lines.jsonl"}"\n')
    script = net.bus("script").session.declare_publisher("pepper/joints/HeadYaw")
    run = spawn(SONIBUS, "run", str(show))
    wait_for(lambda: script.matching_status.matching, timeout=20, what="the sink's subscription")
    script.put(msgpack.packb({"t": 1.0, "seq": 0, "v": 0.1}))
    wait_for(lambda: (tmp_path / "lines.jsonl").exists() and (tmp_path / "lines.jsonl").read_text(),
             what="a good sample written")
    script.put(b"\xc1 not msgpack")
    wait_for(lambda: run.popen.poll() is not None, timeout=10, what="sonibus run to end")
    code, _, err = run.stop()
    assert code == 1, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("sonibus: error: node 'lines': worker 'write' failed: "), err


class Flaky(Adapter):
    """A worker that raises on its first run, then works: spawned with ``restart=True``."""

    @dataclass(frozen=True)
    class Config:
        restart: bool = True

    def _start(self) -> None:
        self.runs = 0
        self.working = threading.Event()
        self.spawn(self._work, "work", restart=self.config.restart)

    def _work(self) -> None:
        self.runs += 1
        if self.runs == 1:
            raise RuntimeError("first run fails")
        self.working.set()
        self.stopping.wait()


def test_a_restartable_worker_runs_again_and_the_node_stays_up(net, caplog):
    flaky = net.start(Flaky(name="flaky"))
    wait_for(flaky.working.is_set, what="the second run")
    assert flaky.state == "running" and not flaky.failure and flaky.runs == 2
    assert "worker 'work' failed: RuntimeError: first run fails; restarting it" in caplog.text


def test_a_worker_that_may_not_restart_fails_the_node(net):
    flaky = net.start(Flaky(Flaky.Config(restart=False), name="flaky"))
    wait_for(lambda: flaky.state == "failed", what="the node to fail")
    assert flaky.failure == "worker 'work' failed: RuntimeError: first run fails" and flaky.runs == 1


def test_sonibus_nodes_shows_a_failed_node_and_why(net):
    flaky = net.start(Flaky(Flaky.Config(restart=False), name="flaky"))
    wait_for(lambda: flaky.state == "failed", what="the node to fail")
    out = io.StringIO()
    assert main(["nodes", *net.cli_args(), "--timeout", "2"], Environment(stdout=out, stderr=io.StringIO())) == 0
    (line,) = [line for line in out.getvalue().splitlines() if "flaky" in line]
    assert line.endswith("FAILED: worker 'work' failed: RuntimeError: first run fails"), line


def test_ctrl_c_while_a_worker_is_being_spawned_stops_the_node_cleanly(net, monkeypatch):
    """SIGINT can land in ``spawn`` between the worker's bookkeeping and its start (a
    ``sonibus run`` interrupted as it starts): the node stops, and the Ctrl-C goes on up
    (exit 130), not 'cannot join thread before it is started' (exit 1)."""
    class Busy(Adapter):
        def _start(self) -> None:
            self.spawn(lambda: self.stopping.wait(), "work")

    start = threading.Thread.start

    def interrupted(thread: threading.Thread) -> None:
        if thread.name == "busy:work":  # (Zenoh starts threads of its own meanwhile)
            raise KeyboardInterrupt
        start(thread)

    bus = net.bus("busy")
    node = Busy(name="busy")
    with monkeypatch.context() as patched:
        patched.setattr(threading.Thread, "start", interrupted)
        with pytest.raises(KeyboardInterrupt):
            node.start(bus)
    assert node.state == "stopped" and [t.name for t in node._threads] == ["busy:work"]
    assert not bus.alive(keys.node_token(bus.host, "busy"), timeout=0.5)


class Fussy(Adapter):
    """A node whose subscription's ``skip`` raises on a key it did not expect (a bug of its own)."""

    @dataclass(frozen=True)
    class Config:
        pass

    def _start(self) -> None:
        def skip(key: str) -> bool:
            if key.endswith("surprise"):
                raise KeyError(key)
            return False

        subscriber, self.queue = self.bus.subscribe("pepper/events/*", skip=skip)
        self.own(subscriber)


def test_a_callback_that_raises_fails_its_node_instead_of_zenoh_printing_it(net):
    """A Zenoh callback that raised was printed by Zenoh and forgotten: the node went on
    reporting itself well while hearing nothing (a half-done edit showed it: 0 messages)."""
    fussy = net.start(Fussy(name="fussy"))
    script = net.bus("script").session.declare_publisher("pepper/events/surprise")
    wait_for(lambda: script.matching_status.matching, what="the node's subscription")
    script.put(msgpack.packb({"t": 1.0, "kind": "x"}))
    wait_for(lambda: fussy.state == "failed", what="the node to fail")
    assert fussy.failure == "subscriber to pepper/events/* failed: KeyError: 'pepper/events/surprise'", fussy.failure


class Direct(Adapter):
    """A node taking frames where they arrive (``Streams``' ``direct``, called by the fanout itself):
    it declines odd frames (into its queue) and raises on a frame it did not expect (a bug of its own)."""

    @dataclass(frozen=True)
    class Config:
        pass

    def _start(self) -> None:
        self.taken: list[tuple[str, bytes]] = []

        def direct(key: str, payload: bytes) -> bool:
            if key.startswith("surprise/"):
                raise KeyError(key)
            if decode(payload)["seq"] % 2:
                return False
            self.taken.append((key, payload))
            return True

        self.queue = SampleQueue(16)
        self.own(Streams(self.bus, ["*/joints/*"], self.queue, direct=direct))


def test_a_direct_take_that_raises_fails_its_node_and_what_it_declines_is_queued(net):
    direct = net.start(Direct(name="direct"))
    script = net.bus("script").session
    frames = script.declare_publisher("pepper/frame")
    wait_for(lambda: frames.matching_status.matching, what="the node's subscription")
    for seq in (0, 1):
        frames.put(msgpack.packb({"t": 1.0, "seq": seq, "names": ["HeadYaw"], "v": [0.1]}))
    wait_for(lambda: direct.taken and len(direct.queue), what="a frame taken and one queued")
    assert [decode(payload)["seq"] for _, payload in direct.taken] == [0]
    assert decode(direct.queue.get()[1])["seq"] == 1 and direct.state == "running"
    script.put("surprise/frame", msgpack.packb({"t": 1.0, "seq": 2, "names": ["HeadYaw"], "v": [0.1]}))
    wait_for(lambda: direct.state == "failed", what="the node to fail")
    assert direct.failure == "subscriber to */frame failed: KeyError: 'surprise/frame'", direct.failure
