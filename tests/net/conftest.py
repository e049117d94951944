"""Fixtures of the multi-host tests: a ``Topology`` of network namespaces per test,
stale namespaces of crashed runs removed once per session, and the figures the
tests measured (loss detection, reconnection, bursts) printed at the end."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from .netns import Topology, remove_stale, require_root, root_reason


@pytest.fixture(scope="session")
def _stale_removed() -> None:
    if root_reason() is None:
        remove_stale()


def _topology() -> Iterator[Topology]:
    require_root()
    topo = Topology()
    try:
        yield topo
    finally:
        topo.close()


@pytest.fixture
def topology(_stale_removed: None) -> Iterator[Topology]:
    yield from _topology()


@pytest.fixture(scope="module")
def shared_topology(_stale_removed: None) -> Iterator[Topology]:
    """One topology for the tests of a module that build on each other's set-up."""
    yield from _topology()
