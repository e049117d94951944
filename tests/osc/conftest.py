"""Fixtures of the OSC tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from .pd import Datagrams


@pytest.fixture
def receivers() -> Iterator[Callable[[], Datagrams]]:
    """Makes UDP receivers (``Datagrams``), closed after the test."""
    made: list[Datagrams] = []

    def make() -> Datagrams:
        made.append(Datagrams())
        return made[-1]

    yield make
    for receiver in made:
        receiver.close()
