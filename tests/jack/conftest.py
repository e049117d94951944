"""A private JACK server per test (``tests/jackd.py``) and a JACK client of the
test's own: it plays a sine into the bridge and listens to what comes out."""

from __future__ import annotations

import time
from collections.abc import Iterator

import jack as jack_client
import numpy as np
import pytest

from sonibus.adapters.jack.client import ProcessEnd

from .. import jackd

jack, jack_server = jackd.jack, jackd.jack_server  # the fixtures, shared with tests/midi


class Peer:
    """Client ``tester``: output ``sine`` plays a sine, input ``ear`` keeps all it hears."""

    def __init__(self, server: str, hz: float = 1000.0, amplitude: float = 0.5) -> None:
        self.client = jack_client.Client("tester", no_start_server=True, servername=server)
        self.rate = self.client.samplerate
        self.hz, self.amplitude, self.played = hz, amplitude, 0
        self.sine = self.client.outports.register("sine")
        self.ear = self.client.inports.register("ear")
        self.heard: list[np.ndarray] = []
        self.first_sound: float | None = None  # time.monotonic() of the first block heard louder than 0.1
        self.ending = ProcessEnd()  # (its thread ends before the client closes: see ``ProcessEnd``)
        self.client.set_process_callback(self._process)
        self.client.activate()

    def _process(self, frames: int) -> None:
        self.ending.check()
        n = np.arange(self.played, self.played + frames)
        self.sine.get_array()[:] = self.amplitude * np.sin(2 * np.pi * self.hz * n / self.rate)
        self.played += frames
        self.heard.append(self.ear.get_array().copy())
        if self.first_sound is None and np.abs(self.heard[-1]).max() > 0.1:
            self.first_sound = time.monotonic()

    def recording(self) -> np.ndarray:
        return np.concatenate(self.heard[:]) if self.heard else np.zeros(0, np.float32)

    def ports(self, prefix: str, **kind: bool) -> list[str]:
        """Names of the audio ports on the server starting with ``prefix`` (``is_input=True``...)."""
        return sorted(p.name for p in self.client.get_ports(is_audio=True, **kind) if p.name.startswith(prefix))

    def close(self) -> None:
        self.ending.end(2.0)
        self.client.deactivate()
        self.client.close()


@pytest.fixture
def peer(jack) -> Iterator[Peer]:
    made = Peer(jack)
    yield made
    made.close()


def peak_hz(signal: np.ndarray, rate: int) -> float:
    """The frequency of the strongest component of ``signal`` (Hann window)."""
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(len(signal))))
    return float(np.fft.rfftfreq(len(signal), 1 / rate)[int(np.argmax(spectrum))])
