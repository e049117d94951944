"""An audio chunk on the bus: the gate takes a good one, refuses each bad one in one
line, and a chunk survives the wire unchanged."""

from __future__ import annotations

import time

import msgpack
import numpy as np
import pytest

from sonibus import schemas
from sonibus.bus import keys, messages
from sonibus.bus.audio import AudioChunk
from sonibus.bus.codec import encode
from sonibus.bus.keys import Key
from sonibus.bus.messages import BadMessage, Gate
from sonibus.bus.node import AUDIO

MIC = Key.parse("pepper/audio/mic")


def chunk(**changes: object) -> dict:
    """A 10 ms stereo chunk at 48 kHz, stamped now, with ``changes``."""
    good = {"t": time.time(), "seq": 3, "rate": 48000, "channels": 2, "pcm": bytes(480 * 2 * 2)}
    return {**good, **changes}


def refused(message: object, key: Key = MIC) -> str:
    payload = message if isinstance(message, bytes) else msgpack.packb(message, use_bin_type=True)
    with pytest.raises(BadMessage) as caught:
        Gate().check(key, payload)
    reason = str(caught.value)
    assert reason and "\n" not in reason and len(reason) < 200, reason
    return reason


def test_the_audio_keys_are_a_robots_mic_and_speaker():
    assert keys.audio("pepper", "mic") == "pepper/audio/mic"
    assert keys.audio("pepper", "speaker") == "pepper/audio/speaker"
    with pytest.raises(ValueError, match="audio stream 'spk' is not one of mic, speaker"):
        keys.audio("pepper", "spk")


def test_a_good_chunk_passes_unchanged_on_either_key():
    for key in (MIC, Key.parse("nao/audio/speaker")):
        for message in (chunk(), chunk(rate=8000, channels=1, pcm=b"\x01\x02"),
                        chunk(rate=192000, channels=8, pcm=bytes(192 * 8 * 2))):
            assert Gate().check(key, encode(message)) == message


@pytest.mark.parametrize(("message", "reason"), [
    (chunk(pcm=bytes(3)), "pcm of 3 bytes is not a whole number of 2-channel int16 frames (4 bytes each"),
    (chunk(pcm=bytes(6)), "pcm of 6 bytes is not a whole number of 2-channel int16 frames"),
    (chunk(channels=3, pcm=bytes(8)), "pcm of 8 bytes is not a whole number of 3-channel int16 frames (6 bytes"),
    (chunk(pcm=b""), "pcm of 0 bytes is not a whole number"),
    (chunk(rate=0), "rate = 0 is not an integer in 8000..192000 Hz"),
    (chunk(rate=10**9), "rate = 1000000000 is not an integer in 8000..192000 Hz"),
    (chunk(rate=48000.0), "rate = 48000.0 is not an integer"),
    (chunk(rate=True), "rate = True is not an integer"),
    (chunk(channels=0), "channels = 0 is not an integer in 1..8"),
    (chunk(channels=9, pcm=bytes(9 * 2)), "channels = 9 is not an integer in 1..8"),
    (chunk(pcm=bytes(4801 * 4)), "4801 frames at 48000 Hz last 100 ms, at most 100 ms"),
    (chunk(rate=8000, channels=1, pcm=bytes(1000 * 2)), "1000 frames at 8000 Hz last 125 ms, at most 100 ms"),
    (chunk(t=-1.0), "t = -1.0 is not a time"),
    (chunk(t=float("nan")), "t = nan is not a time"),
    (chunk(t=time.time() + 3600), "is not a time between 1970 and 5 s from now"),
    (chunk(t="now"), "t = 'now' is not a number"),
    (chunk(seq=-1), "seq = -1 is not an integer in 0.."),
    (chunk(pcm="\x00\x00\x00\x00"), "pcm is a str, not bytes (int16 little-endian, interleaved)"),
    (chunk(pcm=[0, 0, 0, 0]), "pcm is a list, not bytes"),
    (chunk(gain=0.5), "field 'gain' is not one of an audio chunk's (t, seq, rate, channels, pcm)"),
    ({k: v for k, v in chunk().items() if k != "rate"}, "no 'rate'"),
    ({k: v for k, v in chunk().items() if k != "pcm"}, "no 'pcm'"),
    (encode(chunk())[:-100], "payload is not msgpack"),
    (chunk(pcm=bytes(16_400 * 4)), "over the limit of 65536"),
])
def test_bad_chunks_are_refused_saying_why(message, reason):
    assert reason in refused(message)


def test_an_audio_key_of_no_stream_is_refused():
    assert refused(chunk(), Key.parse("pepper/audio/radio")) == "'radio' is not an audio stream (mic, speaker)"


def test_the_gate_reads_its_audio_bounds_from_the_schema():
    schema = schemas.load("audio_chunk")
    assert (messages.MIN_RATE, messages.MAX_RATE, messages.MAX_CHANNELS) == (8000, 192000, 8)
    assert messages.MAX_CHUNK_S == schema["x-max-duration-s"] == 0.1
    assert messages.schema_of(MIC) == "audio_chunk"
    without_pcm = {k: v for k, v in chunk().items() if k != "pcm"}
    assert not schemas.validator("audio_chunk").is_valid(without_pcm)  # pcm is required there too
    for field, value in (("rate", 7999), ("channels", 9), ("seq", -1), ("extra", 1)):
        assert not schemas.validator("audio_chunk").is_valid({**chunk(), field: value}), field


def test_a_chunk_goes_from_samples_over_the_wire_and_back_unchanged():
    t = time.time()
    sine = np.sin(2 * np.pi * 440 * np.arange(320) / 16000)
    samples = np.stack([sine, -sine, 0.5 * sine, np.zeros(320)], axis=1)   # 20 ms of four microphones
    sent = AudioChunk.from_samples(t, 41, 16000, samples)
    assert (sent.frames, sent.channels, sent.duration) == (320, 4, 0.02)
    got = AudioChunk.of(Gate().check(MIC, encode(sent.message())))
    assert got == sent
    assert got.samples().dtype == np.int16 and got.samples().shape == (320, 4)
    assert np.abs(got.samples() / 32767 - samples).max() <= 0.5 / 32767
    assert got.pcm[:4] == np.array([0, 0], "<i2").tobytes()                     # little-endian on the wire


def test_from_samples_takes_int16_and_float_clipped_and_refuses_other_types():
    ints = np.array([[1, -2], [32767, -32768]], np.int16)
    assert AudioChunk.from_samples(0.0, 0, 8000, ints).samples().tolist() == ints.tolist()
    loud = AudioChunk.from_samples(0.0, 0, 8000, np.array([2.0, -3.0, 0.25], np.float32))
    assert loud.channels == 1 and loud.samples()[:, 0].tolist() == [32767, -32767, 8192]
    with pytest.raises(TypeError, match="dtype int32: int16, or float in \\[-1, 1\\], expected"):
        AudioChunk.from_samples(0.0, 0, 8000, np.zeros((4, 1), np.int32))
    with pytest.raises(ValueError, match="shape"):
        AudioChunk.from_samples(0.0, 0, 8000, np.zeros((0, 2)))


def test_audio_is_published_dropped_under_congestion_and_without_batching():
    assert AUDIO.drop and AUDIO.express
    options = AUDIO.options()
    assert options["express"] is True and str(options["congestion_control"]).endswith("DROP")


def test_a_robot_says_in_its_info_what_audio_it_has():
    info = {"robot": "pepper", "model": "pepper", "rate_hz": 50.0, "behaviors": [], "postures": [],
            "adapter": "x", "schema_version": 1, "owner": {"host": "h", "node": "n"},
            "joints": [{"name": "HeadYaw", "unit": "rad", "min": -2.0, "max": 2.0, "max_velocity": 7.0}]}
    key = Key.parse("pepper/info")
    for audio in ({"mic": {"rate": 16000, "channels": 4}, "speaker": {"rate": 48000, "channels": 2}},
                  {"mic": None, "speaker": {"rate": 48000, "channels": 2}}):
        with_audio = {**info, "audio": audio}
        assert Gate().check(key, encode(with_audio)) == with_audio
    assert Gate().check(key, encode(info)) == info                                    # absent: no audio
    bad = {**info, "audio": {"mic": {"rate": 16000, "channels": 0}, "speaker": None}}
    with pytest.raises(BadMessage, match="not a valid robot info: audio/mic"):
        Gate().check(key, encode(bad))
