"""Fixtures of the show's tests: the multi-host tests' network namespaces (a day of
museum.toml runs in one of its own, its fixed ports and multicast inside it)."""

from ..net.conftest import _stale_removed, topology

__all__ = ["_stale_removed", "topology"]
