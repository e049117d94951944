"""The audio bridge end to end: a private JACK server (dummy driver) with the test's
own JACK client, the ``jack`` adapter, the ``naoqi`` adapter and naoqi-sim's
ALAudioDevice on a real libqi session, real Zenoh sessions between them."""

from __future__ import annotations

from .. import jackd
from ..jack import conftest as jack_tests
from ..naoqi import conftest as naoqi_tests
from ..naoqi import test_audio as naoqi_audio_tests

jack = jackd.jack  # the fixtures, shared with tests/jack and tests/naoqi
peer = jack_tests.peer
fakes = naoqi_tests.fakes
rig = naoqi_tests.rig
qi_client = naoqi_audio_tests.qi_client  # qi_client(url): a libqi session, closed after the test
