"""A real recording to work on: the simulator, with a behavior and speech,
recorded by the recorder for a couple of seconds."""

from __future__ import annotations

import contextlib
import os
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.adapters.sim import SimConfig, SimRobot
from sonibus.bus import SampleQueue, decode, robot_info, send_command

from ..conftest import Network, wait_for

HEY = "animations/Stand/Gestures/Hey_1"


def record_sim(net: Network, path: Path, frames: int = 100, rate_hz: float = 50.0, robot: type[SimRobot] = SimRobot,
               **options: Any) -> tuple[Recorder, list[tuple[str, dict[str, Any]]]]:
    """Record a simulated pepper (a ``robot``, idle, running a behavior and speech) for ``frames`` frames.

    Returns the recorder, stopped, and what an independent subscriber saw on the
    bus meanwhile. The robot stops first, so both hold every frame it sent."""
    recorder = net.start(Recorder(RecorderConfig(path=str(path), **options), name="logger"))
    watch = net.bus("watch")
    seen = SampleQueue(1 << 20)
    subscribers = [watch.subscribe(p, queue=seen)[0] for p in ("pepper/joints/*", "pepper/events/*")]
    sim = net.start(robot(SimConfig(robot="pepper", rate_hz=rate_hz, idle=True, body_sound=False),  # (audio:
                          name="sim-pepper"))                                          # test_audio.py)
    wait_for(lambda: robot_info(watch, "pepper", timeout=0.5), what="pepper/info")
    send_command(watch, "pepper", "behavior/run", {"name": HEY})
    send_command(watch, "pepper", "say", {"text": "hello there"})
    reference: list[tuple[str, dict[str, Any]]] = []

    def drain() -> int:
        while (item := seen.get(timeout=0)) is not None:
            reference.append((item[0], decode(item[1])))
        return sum(1 for key, _ in reference if key == "pepper/joints/HeadYaw")

    wait_for(lambda: drain() >= frames, timeout=frames / rate_hz * 5, what=f"{frames} frames")
    sim.stop()
    settle(lambda: (drain(), recorder.stats["received"]))
    for subscriber in subscribers:
        subscriber.undeclare()
    recorder.stop()
    return recorder, reference


def settle(state: Any, quiet_s: float = 0.3, timeout: float = 10.0) -> None:
    """Until ``state()`` stops changing for ``quiet_s`` (everything in flight has arrived)."""
    last: list[Any] = [object(), 0.0]

    def quiet() -> bool:
        now = state()
        if now != last[0]:
            last[0], last[1] = now, time.monotonic()
        return time.monotonic() - last[1] >= quiet_s

    wait_for(quiet, timeout, "the bus to go quiet")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[tuple[str, dict[str, Any]]]]:
    """A finished recording and what the bus carried meanwhile, shared by a module's
    tests (which must not change the file)."""
    path = tmp_path_factory.mktemp("rec") / "pepper.mcap"
    network = Network()
    try:
        _, reference = record_sim(network, path)
    finally:
        network.close()
    return path, reference


@contextlib.contextmanager
def tmpfs(size: str) -> Iterator[str]:
    """A file system of ``size`` (``256k``, ``2m``) of its own, a real one (tmpfs) that
    fills for real, unmounted whatever happens."""
    folder = tempfile.mkdtemp(prefix="sonibus-disk-")
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", folder], check=True)
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", folder], check=False)
        os.rmdir(folder)
