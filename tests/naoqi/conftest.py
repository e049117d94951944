"""The ``naoqi`` adapter against the simulator's fake NAOqi endpoint: a real libqi
session on loopback, real Zenoh sessions for the bus."""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from sonibus.adapters.naoqi import NaoqiConfig, NaoqiRobot
from sonibus.adapters.sim.naoqi import FakeNaoqi, FakeNaoqiConfig
from sonibus.bus import Bus

from ..conftest import SONIBUS, Process, free_port, wait_for
from ..test_commands import Events, Joints

RATE_HZ = 50


@dataclass
class NaoqiRig:
    """A fake robot, the adapter that owns it, and a client on another session."""

    name: str
    fake: FakeNaoqi | None
    adapter: NaoqiRobot
    bus: Bus
    joints: Joints
    events: Events


@pytest.fixture
def fakes() -> Iterator[Callable[..., FakeNaoqi]]:
    """``fakes(port=None, **FakeNaoqiConfig options)``: a started fake, stopped after the test."""
    started: list[FakeNaoqi] = []

    def start(port: int | None = None, **options: Any) -> FakeNaoqi:
        options = {"rate_hz": 100, **options}
        fake = FakeNaoqi(FakeNaoqiConfig(listen=f"tcp://127.0.0.1:{port or free_port()}", **options)).start()
        started.append(fake)
        return fake

    yield start
    for fake in started:
        fake.stop()


def attach(net: Any, url: str, robot: str = "pepper", wait: bool = True, fake: FakeNaoqi | None = None,
           **options: Any) -> NaoqiRig:
    """The client subscribes first (so it sees ``connection`` events), then the adapter starts."""
    client = net.bus(f"client-{robot}")
    events = Events(client, f"{robot}/events/*")
    joints = Joints(client, robot)
    options = {"rate_hz": RATE_HZ, "retry_max_s": 0.5, "connect_timeout_s": 2.0, **options}
    adapter = net.start(NaoqiRobot(NaoqiConfig(robot=robot, url=url, **options), name=f"naoqi-{robot}"))
    if wait:
        wait_for(joints.complete, what=f"a complete frame from {robot}")
    return NaoqiRig(robot, fake, adapter, client, joints, events)


@pytest.fixture
def rig(fakes: Callable[..., FakeNaoqi], net: Any) -> Callable[..., NaoqiRig]:
    """``rig(robot="pepper", fake={...}, **NaoqiConfig options)``: a fake robot owned by the adapter
    (``fakes`` before ``net``: the adapter stops before its robot does)."""

    def make(robot: str = "pepper", fake: dict[str, Any] | None = None, **options: Any) -> NaoqiRig:
        endpoint = fakes(model=robot.rstrip("0123456789"), **(fake or {}))
        return attach(net, endpoint.url, robot, fake=endpoint, **options)

    return make


@dataclass
class FakeProcess:
    """A fake robot in a ``sonibus run`` process of its own, so it can be frozen like a hung robot."""

    url: str
    process: Process

    def freeze(self) -> None:
        """SIGSTOP: the robot stops answering; its sockets stay open (the kernel still accepts)."""
        os.kill(self.process.popen.pid, signal.SIGSTOP)

    def resume(self) -> None:
        os.kill(self.process.popen.pid, signal.SIGCONT)


@pytest.fixture
def fake_process(tmp_path: Path, spawn: Callable[..., Process]) -> Callable[..., FakeProcess]:
    """``fake_process(**naoqi-sim options)``: a naoqi-sim node in its own process, killed after the test."""

    def start(**options: Any) -> FakeProcess:
        url = f"tcp://127.0.0.1:{free_port()}"
        show = tmp_path / f"fake-{free_port()}.toml"
        show.write_text(toml_node("fake", adapter="naoqi-sim", listen=url, rate_hz=50, **options))
        process = spawn(SONIBUS, "-v", "run", str(show), "--no-multicast", "--listen",
                        f"tcp/127.0.0.1:{free_port()}", collect=True, merge=True)
        wait_for(lambda: any("fake NAOqi" in line for line in process.lines) or process.popen.poll() is not None,
                 timeout=20.0, what="the fake robot process", explain=lambda: "\n".join(process.lines))
        assert process.popen.poll() is None, "\n".join(process.lines)
        return FakeProcess(url, process)

    return start


def toml_node(name: str, **options: Any) -> str:
    """One ``[nodes.<name>]`` table (strings, numbers and booleans)."""
    lines = [f"[nodes.{name}]"]
    for key, value in options.items():
        shown = json.dumps(value) if isinstance(value, str | bool) else repr(value)
        lines.append(f"{key} = {shown}")
    return "\n".join(lines) + "\n"
