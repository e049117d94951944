"""Audio features against their closed forms: a sine of amplitude A is 20·log10(A/√2) dB,
a sine of f Hz has its centroid at f, an impulse in silence is an onset (and nothing
else is); and the ``hear`` node on a real bus publishes them with their ranges."""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import replace

import numpy as np
import pytest

from sonibus.adapters.hear import Hear, HearConfig, Onsets, centroid_hz, level_db
from sonibus.adapters.hear.features import FLOOR_DB
from sonibus.bus import codec, keys
from sonibus.bus.audio import AudioChunk
from sonibus.bus.node import AUDIO

from ..conftest import wait_for
from ..map.test_node import Listen

RATE = 48000


def sine(hz: float, amplitude: float = 0.5, frames: int = 480, rate: int = RATE, phase: float = 0.0) -> np.ndarray:
    return amplitude * np.sin(2 * np.pi * hz * np.arange(frames) / rate + phase)


@pytest.mark.parametrize("amplitude", [1.0, 0.5, 0.1, 0.001])
def test_a_sine_of_known_amplitude_gives_its_db(amplitude):
    # 1 kHz at 48 kHz: 480 frames are ten whole periods, where the RMS of A·sin is exactly A/√2
    assert level_db(sine(1000, amplitude)) == pytest.approx(20 * math.log10(amplitude / math.sqrt(2)), abs=1e-9)
    stereo = np.stack([sine(1000, amplitude), sine(1000, amplitude, phase=1.0)], axis=1)  # (every channel counts)
    assert level_db(stereo) == pytest.approx(20 * math.log10(amplitude / math.sqrt(2)), abs=1e-9)


def test_silence_is_the_floor_not_minus_infinity():
    assert level_db(np.zeros(480)) == FLOOR_DB
    assert centroid_hz(np.zeros(480), RATE) == 0.0


@pytest.mark.parametrize("hz", [300.0, 1000.0, 2500.0, 8000.0])
def test_a_sine_of_known_frequency_has_its_centroid_there(hz):
    # 2048 frames (23 Hz bins), Hann window: the leakage is symmetric about f, so the centroid is f
    assert centroid_hz(sine(hz, frames=2048), RATE) == pytest.approx(hz, rel=0.01)


def test_two_sines_of_equal_amplitude_have_their_centroid_between_them():
    both = sine(1000, 0.3, 4800) + sine(3000, 0.3, 4800)
    assert centroid_hz(both, RATE) == pytest.approx(2000, rel=0.01)


def test_an_impulse_has_a_flat_spectrum_so_its_centroid_is_half_the_nyquist_frequency():
    assert centroid_hz(np.eye(1, 4096, 2048)[0], RATE) == pytest.approx(RATE / 4, rel=1e-6)  # (mid-window)


def test_an_impulse_in_silence_is_an_onset_and_nothing_else_is():
    onsets = Onsets()
    chunks = [np.zeros(480)] * 20 + [np.eye(1, 480, 100)[0] * 0.9] + [np.zeros(480)] * 20
    found = [i for i, chunk in enumerate(chunks) if onsets(i * 0.01, level_db(chunk))]
    assert found == [20]


def test_a_steady_sound_is_one_onset_at_its_start_and_a_second_clap_another():
    onsets = Onsets(hold_s=0.15)
    levels = [-90.0] * 10 + [-20.0] * 50 + [-90.0] * 30 + [-10.0] + [-90.0] * 10
    found = [i for i, db in enumerate(levels) if onsets(i * 0.01, db)]
    assert found == [10, 90]


def test_the_node_publishes_the_features_of_a_sine_with_their_ranges(net):
    node = net.start(Hear(HearConfig(listen=("pepper/audio/mic",)), name="ears"))
    watch = net.bus("watch")
    heard = Listen(watch, "pepper/derived/**")
    robot = net.bus("robot")
    # (AUDIO's, but blocking: the five chunks below go at once, and AUDIO drops what waits over a
    # millisecond: on a busy machine 3 of 5; what the node makes of the chunks it gets is the test)
    publisher = robot.stream_publisher(keys.audio("pepper", "mic"), replace(AUDIO, drop=False))
    info = wait_for(lambda: watch.query(keys.derived_info("pepper"), timeout=0.5), what="the node's info")
    described = {e["name"]: e for e in info[0]["derived"]}
    assert (described["loudness/mic"]["unit"], described["loudness/mic"]["min"], described["loudness/mic"]["max"]) \
        == ("dB", FLOOR_DB, 0.0)
    assert described["centroid/mic"]["unit"] == "Hz" and described["onset/mic"]["max"] == 1.0
    # before any audio: silence, said as a signal (-100 dB), not nothing
    wait_for(lambda: heard.on("pepper/derived/loudness/mic"), what="the silence before any audio")
    assert heard.on("pepper/derived/loudness/mic")[0]["v"] == FLOOR_DB
    times = []
    for seq in range(5):  # 1 kHz at half scale, 10 ms chunks of 16 kHz (whole periods)
        chunk = AudioChunk.from_samples(time.time(), seq, 16000, sine(1000, 0.5, 160, 16000))
        times.append(chunk.t)
        publisher.put(codec.encode(chunk.message()))

    def of_chunks(feature: str) -> list[float]:
        return [m["v"] for m in heard.on(f"pepper/derived/{feature}/mic") if m["t"] in times]

    wait_for(lambda: len(of_chunks("centroid")) == 5, what="five centroids",
             explain=lambda: f"{of_chunks('centroid')}; node {node.stats}; times {times}; "
                             f"loudness {[(m['t'], m['v']) for m in heard.on('pepper/derived/loudness/mic')]}")
    assert of_chunks("loudness") == pytest.approx([20 * math.log10(0.5 / math.sqrt(2))] * 5, abs=0.01)  # (int16)
    assert of_chunks("centroid")[-1] == pytest.approx(1000, rel=0.05)  # (100 Hz bins)
    assert of_chunks("onset") == [1.0] * 5  # (the first an onset, the others within its hold)
    # no chunk for quiet_ms: the stream is said silent once, its onset over after the hold
    wait_for(lambda: heard.on("pepper/derived/onset/mic")[-1]["v"] == 0.0, what="the onset's end")
    assert heard.on("pepper/derived/loudness/mic")[-1]["v"] == FLOOR_DB
    assert node.stats["onsets"] == 1
    # a chunk after the silence, stamped (as a chunk is) with its first sample's time, before it arrived:
    # the stream's t still only grows, so no sink's pacing skips it as a sample from the past
    chunk = AudioChunk.from_samples(time.time() - 0.02, 5, 16000, sine(1000, 0.5, 160, 16000))
    publisher.put(codec.encode(chunk.message()))
    wait_for(lambda: node.stats["onsets"] == 2, what="the second onset")
    wait_for(lambda: heard.on("pepper/derived/onset/mic")[-1]["v"] == 0.0, what="its end")
    stamps = [m["t"] for m in heard.on("pepper/derived/onset/mic")]
    assert all(a < b for a, b in itertools.pairwise(stamps)), stamps
    publisher.undeclare()
