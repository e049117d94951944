"""Tests that measure real time take their turn alone.

A few tests assert what only holds when the machine keeps up: steady audio with no
gap through JACK or a robot's speaker, a sink that finds nothing stale as a show
starts. With more workers than cores, another worker's fuzz campaign or network
namespaces can starve them for a moment, and they fail for the machine, not for the
code. Marked ``@pytest.mark.realtime``, such a test waits until the tests running on
the other workers of this run have ended, and none starts until it has.

Two ``flock``s shared by the run's workers (in the run's temporary folder): every test
holds the *running* lock shared; a realtime test holds it alone. The *turnstile* is
taken briefly by every test before it and held by a realtime test while it waits,
so a stream of ordinary tests cannot keep it waiting for ever. The kernel releases
both when a worker dies. Outside xdist there is nobody to wait for.

Only the tests themselves wait: a module's fixture started on another worker (a show,
a JACK server) keeps running meanwhile, so "alone" is among the tests, not the machine.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

WAIT_S = 600.0  # longer than any one test runs: past it, something holds a lock it should not


def _lock(file: int, how: int, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while True:
        try:
            fcntl.flock(file, how | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() > deadline:
                raise RuntimeError(f"waited {WAIT_S:.0f} s for {what}: another worker holds it") from None
            time.sleep(0.02)


@contextlib.contextmanager
def turn(alone: bool, folder: Path) -> Iterator[None]:
    """Hold this run's running lock (its files in ``folder``, the same for every worker of the
    run), shared, or ``alone`` (with the turnstile held while waiting)."""
    if not os.environ.get("PYTEST_XDIST_TESTRUNUID"):
        yield
        return
    folder.mkdir(exist_ok=True)
    turnstile = os.open(folder / "turnstile", os.O_RDWR | os.O_CREAT, 0o600)
    running = os.open(folder / "running", os.O_RDWR | os.O_CREAT, 0o600)
    try:
        _lock(turnstile, fcntl.LOCK_EX, "the turnstile")
        try:
            _lock(running, fcntl.LOCK_EX if alone else fcntl.LOCK_SH,
                  "the other workers' tests to end" if alone else "a realtime test to end")
        finally:
            fcntl.flock(turnstile, fcntl.LOCK_UN)
        yield
    finally:
        os.close(running)  # (closing drops the lock)
        os.close(turnstile)


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    # (beside the workers' own temporary folders, in the run's: pytest removes it with them, later)
    folder = item.config._tmp_path_factory.getbasetemp().parent / "turns"
    with turn(alone=item.get_closest_marker("realtime") is not None, folder=folder):
        yield
