"""The suite's own turn-taking (tests/turns.py): a realtime test runs while no other
worker's test does, and ordinary tests arriving meanwhile do not keep it waiting."""

from __future__ import annotations

import threading

from .conftest import wait_for
from .turns import turn


def test_a_realtime_test_waits_for_the_running_ones_and_then_runs_alone(monkeypatch, tmp_path):
    monkeypatch.setenv("PYTEST_XDIST_TESTRUNUID", "a run of its own")
    folder = tmp_path / "turns"
    said: list[str] = []
    first_may_end, late_may_start = threading.Event(), threading.Event()

    def ordinary(name: str, until: threading.Event) -> None:
        with turn(alone=False, folder=folder):
            said.append(f"{name} runs")
            until.wait(10)
        said.append(f"{name} ended")

    def realtime() -> None:
        with turn(alone=True, folder=folder):
            said.append("realtime runs")
            late_may_start.set()  # (the late one tries now, and must wait for this to end)
            wait_for(lambda: late.is_alive(), what="the late ordinary test to try")
            said.append("realtime ends")

    first = threading.Thread(target=ordinary, args=("first", first_may_end))
    first.start()
    wait_for(lambda: "first runs" in said, what="the first ordinary test to run")
    alone = threading.Thread(target=realtime)
    alone.start()
    done = threading.Event()
    done.set()
    late = threading.Thread(target=lambda: (late_may_start.wait(10), ordinary("late", done)))
    wait_for(lambda: alone.is_alive(), what="the realtime test to wait")
    assert "realtime runs" not in said  # (the first still runs)
    late.start()
    first_may_end.set()
    for thread in (first, alone, late):
        thread.join(15)
    assert said.index("first ended") < said.index("realtime runs") < said.index("realtime ends") \
        < said.index("late runs"), said


def test_outside_xdist_nobody_waits(monkeypatch, tmp_path):
    monkeypatch.delenv("PYTEST_XDIST_TESTRUNUID", raising=False)
    # (the same worker twice: in a run it would wait for itself)
    with turn(alone=True, folder=tmp_path), turn(alone=True, folder=tmp_path):
        pass
