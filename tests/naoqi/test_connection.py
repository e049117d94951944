"""A robot that is not there yet, goes away and comes back: the node stays up,
says so on the bus, and streams again on its own."""

from __future__ import annotations

import socket
import threading
import time

import pytest

from sonibus import schemas
from sonibus.bus import CommandError, robot_info, send_command

from ..conftest import SONIBUS, free_port, wait_for
from .conftest import attach, toml_node

NOD = "animations/Stand/Gestures/Yes_1"


def refused(rig, verb, args):
    with pytest.raises(CommandError) as caught:
        send_command(rig.bus, rig.name, verb, args)
    return caught.value


def test_unreachable_at_start_then_the_robot_appears(net, fakes):
    port = free_port()
    r = attach(net, f"tcp://127.0.0.1:{port}", wait=False)
    assert r.adapter.state == "running", "start() waited for the robot"  # nothing listens on the port yet
    lost = r.events.wait("connection", state="lost")
    assert str(port) in lost["url"] and lost["error"]
    info = robot_info(r.bus, "pepper")
    schemas.validate("robot_info", info)
    assert info["naoqi"]["connected"] is False and info["model"] == "pepper"  # the reference model until then
    for verb, args in (("say", {"text": "hello"}), ("behavior/run", {"name": NOD})):
        error = refused(r, verb, args)
        assert error.code == "not_connected", (verb, error)
        assert "not connected" in error.message and str(port) in error.message and "\n" not in error.message
    stop = send_command(r.bus, "pepper", "stop", {})  # never refused, never said done when it was not
    assert stop["reached"] is False and stop["connection"] == "lost" and stop["pending"] is True, stop
    assert str(port) in stop["error"]
    assert refused(r, "joints/set", {"names": ["HeadYaw"], "angles": [9.0]}).code == "out_of_range"
    fakes(port)
    r.events.wait("connection", timeout=5.0, state="connected")
    wait_for(r.joints.complete, what="frames once the robot is there")
    assert [e["state"] for e in r.events.find("connection")] == ["connecting", "lost", "connected"]
    assert send_command(r.bus, "pepper", "behavior/run", {"name": NOD}) == {"name": NOD}


def test_robot_lost_mid_stream_and_back_on_the_same_port(net, fakes):
    port = free_port()
    fake = fakes(port)
    r = attach(net, fake.url)
    r.events.wait("connection", state="connected")
    before = r.joints.last()[0]
    fake.stop()
    r.events.wait("connection", timeout=3.0, state="lost")
    assert robot_info(r.bus, "pepper")["naoqi"]["connected"] is False
    assert "not connected" in refused(r, "say", {"text": "anyone?"}).message
    outage = r.joints.last()[0]
    fake = fakes(port)  # a new robot process on the same address
    wait_for(lambda: len(r.events.find("connection", state="connected")) == 2, timeout=5.0,
             what="connected again")
    after = r.joints.next(5)
    assert after[0][0] > outage >= before  # seq goes on, with a gap for the outage
    fake.engine.joints_set(["HeadYaw"], [0.4], 1.0)
    r.joints.wait_pose({"HeadYaw": 0.4}, tol=1e-6)
    send_command(r.bus, "pepper", "behavior/run", {"name": NOD})  # signals are connected again too
    r.events.wait("behavior", name=NOD, state="started")
    assert [e["state"] for e in r.events.find("connection")] == ["connecting", "connected", "lost", "connected"]


def test_stop_is_prompt_connected_retrying_and_mid_connect(net, fakes, caplog):
    fake = fakes()
    connected = attach(net, fake.url)
    retrying = attach(net, f"tcp://127.0.0.1:{free_port()}", robot="pepper2", wait=False)
    with socket.socket() as silent:  # accepts, never answers: the connect hangs until its timeout
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        hanging = attach(net, f"tcp://127.0.0.1:{silent.getsockname()[1]}", robot="pepper3", wait=False,
                         connect_timeout_s=30.0)
        retrying.events.wait("connection", state="lost")
        silent.settimeout(5.0)
        accepted, _ = silent.accept()  # the third adapter is in its connect, and stays there
        with accepted:
            for rig in (connected, retrying, hanging):
                started = time.monotonic()
                rig.adapter.stop()
                # within the node's 3 s (not the 30 s connect), every worker ending by itself (none left behind)
                assert time.monotonic() - started < 3.0, rig.name
                assert rig.adapter.state == "stopped"
    assert "did not stop within" not in caplog.text


def test_the_connection_line_names_the_robot_at_the_default_level(net, fakes, spawn, tmp_path):
    fake = fakes(robot_name="Juliette")
    show = tmp_path / "show.toml"
    show.write_text(toml_node("pepper", adapter="naoqi", url=fake.url))
    robot = spawn(SONIBUS, "run", str(show), *net.cli_args(), collect=True, merge=True)  # no -v
    lines = wait_for(lambda: [line for line in robot.lines if "connected to" in line], timeout=20.0,
                     what="the connection line", explain=lambda: "\n".join(robot.lines))
    assert lines[0].startswith(f"sonibus: INFO: pepper: connected to Pepper 'Juliette' at {fake.url} "
                               "(NAOqi 2.5.10.7): 17 joints from almemory"), lines
    assert robot.stop()[0] == 130


def test_nothing_is_sent_on_a_session_that_was_replaced(fakes):
    """libqi crashed the process when a call went out on a session being closed: a call, a
    signal or a module meant for a replaced session is refused (``LinkDown``) and not sent."""
    from sonibus.adapters.naoqi import NaoqiConfig, connection
    from sonibus.adapters.naoqi.connection import Link, LinkDown

    robot = fakes()
    link = Link(NaoqiConfig(url=robot.url, connect_timeout_s=2.0), on_lost=lambda reason: None)
    try:
        link.connect()
        old, session = link.current()
        system = link.service("ALSystem")
        assert link.call("ALSystem", "robotName") is not None
        link.connect()  # the link is replaced: a new session
        new, _ = link.current()
        assert new != old
        with pytest.raises(LinkDown, match="replaced"):
            link.send(old, system.robotName)
        with pytest.raises(LinkDown, match="replaced"):
            link.send(old, session.registerService, "stale_module", object())
        assert link.service("ALSystem") is not system, "a proxy of the closed session was reused"
        assert link.call("ALSystem", "robotName") is not None
        assert session in [s for _, s in connection._retired], "a closed session is kept a while, not freed at once"
    finally:
        link.close()
    assert link.session is None


class WatchedLock:
    """A lock that notes when a thread other than its holder waits for it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.waited = threading.Event()

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        if not self._lock.acquire(blocking=False):
            self.waited.set()
            return self._lock.acquire(blocking, timeout)
        return True

    def release(self) -> None:
        self._lock.release()

    def __enter__(self) -> WatchedLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def test_a_connect_waits_for_a_close_under_way_and_a_drop_meanwhile_wins(fakes):
    """Connecting is sent like a call: not while a session is being closed (the send lock is
    held), and not at all once the link was dropped meanwhile; ``connect`` says so (``LinkDown``)
    rather than return with the link not connected."""
    from sonibus.adapters.naoqi import NaoqiConfig
    from sonibus.adapters.naoqi.connection import Link, LinkDown

    robot = fakes()
    link = Link(NaoqiConfig(url=robot.url, connect_timeout_s=5.0), on_lost=lambda reason: None)
    link._sending = sending = WatchedLock()
    outcome: dict[str, object] = {}

    def connect() -> None:
        try:
            link.connect()
            outcome["connect"] = "returned"
        except LinkDown as exc:
            outcome["connect"] = exc

    connecting = threading.Thread(target=connect)
    dropping = threading.Thread(target=link.drop)
    try:
        with sending:  # a close under way
            connecting.start()
            wait_for(lambda: sending.waited.is_set() or "connect" in outcome, what="the connect to wait or return")
            assert "connect" not in outcome, "connect went out while a session was being closed"
            assert link.session is not None and not link.connected
            dropping.start()  # (a stop: it closes the new session once the send lock is free)
            wait_for(lambda: link.session is None, what="the drop to take the session")
        connecting.join(10.0)
        dropping.join(10.0)
        assert isinstance(outcome["connect"], LinkDown), outcome
        assert not link.connected and link.session is None
    finally:
        link.close()


def test_a_closed_link_opens_no_session_again(fakes):
    """``close`` is for good: the adapter's reader, connecting (or about to) when the node stops,
    opened a session after the stop closed the link; nothing closed that one."""
    from sonibus.adapters.naoqi import NaoqiConfig
    from sonibus.adapters.naoqi.connection import Link, LinkDown

    robot = fakes()
    link = Link(NaoqiConfig(url=robot.url, connect_timeout_s=5.0), on_lost=lambda reason: None)
    link.connect()
    link.close()
    try:
        with pytest.raises(LinkDown, match="closed"):
            link.connect()
        assert link.session is None and not link.connected
    finally:
        link.close()


def test_the_sessions_of_a_closed_link_are_not_freed_at_its_close(fakes):
    """The node's threads stop after it closes the link, and libqi crashed when a session was
    freed with work on it still under way: a closed link's sessions outlive it for a while."""
    import gc
    import weakref

    from sonibus.adapters.naoqi import NaoqiConfig
    from sonibus.adapters.naoqi.connection import Link

    robot = fakes()
    link = Link(NaoqiConfig(url=robot.url, connect_timeout_s=2.0), on_lost=lambda reason: None)
    link.connect()
    first = weakref.ref(link.current()[1])
    link.connect()
    last = weakref.ref(link.current()[1])
    link.close()
    del link
    gc.collect()
    assert first() is not None and last() is not None, "a session was freed at the close of its link"
