"""The audio bridge end to end: a private JACK server (dummy driver) with the test's
own JACK client, the ``jack`` adapter, the ``naoqi`` adapter and naoqi-sim's
ALAudioDevice on a real libqi session, real Zenoh sessions between them."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest
import qi

from .. import jackd
from ..jack import conftest as jack_tests
from ..naoqi import conftest as naoqi_tests

jack = jackd.jack  # the fixtures, shared with tests/jack and tests/naoqi
peer = jack_tests.peer
fakes = naoqi_tests.fakes
rig = naoqi_tests.rig


@pytest.fixture
def qi_session() -> Iterator[Callable[[str], Any]]:
    """``qi_session(url)``: a libqi session connected to ``url``, closed after the test."""
    sessions: list[Any] = []

    def connect(url: str) -> Any:
        session = qi.Session()
        session.connect(url)
        sessions.append(session)
        return session

    yield connect
    for session in sessions:
        session.close()
