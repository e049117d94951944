"""NAOqi audio against naoqi-sim's ALAudioDevice on a real libqi session: the
speaker (<robot>/audio/speaker → jitter buffer → sendRemoteBufferToOutput) and
the microphones (processRemote → <robot>/audio/mic, only while anyone listens)."""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
import qi
import soundfile

from sonibus import schemas
from sonibus.adapters.naoqi import NaoqiConfig
from sonibus.adapters.naoqi.speaker import MAX_FRAMES
from sonibus.adapters.sim.naoqi_audio import ALAudioDevice
from sonibus.bus import Bus, codec, keys, messages, robot_info, send_command
from sonibus.bus.audio import AudioChunk
from sonibus.bus.errors import ConfigError
from sonibus.bus.node import AUDIO
from sonibus.bus.options import from_mapping

from ..conftest import wait_for
from .conftest import NaoqiRig, attach
from .relay import Relay

OUT = 48000          # the robot's output rate
CEILING = 0.25       # the adapter's default volume ceiling
QUIET = 100          # |sample| at or below this is silence (a full-scale sine × 0.25 peaks at 8192)
EXIT_BOUND_S = 3.0


# -- helpers ---------------------------------------------------------------------------------


def sine_chunks(hz: float, rate: int, seconds: float, chunk_ms: float = 20.0, amplitude: float = 1.0,
                skip: tuple[int, ...] = ()) -> list[AudioChunk]:
    """Consecutive mono chunks of a sine (``skip``: seqs left out, as lost on the way)."""
    step = round(rate * chunk_ms / 1000)
    start, chunks = time.time(), []
    for seq in range(round(seconds * 1000 / chunk_ms)):
        n = np.arange(seq * step, (seq + 1) * step)
        if seq not in skip:
            chunks.append(AudioChunk.from_samples(start + seq * step / rate, seq, rate,
                                                  amplitude * np.sin(2 * np.pi * hz * n / rate)))
    return chunks


def play(bus: Bus, robot: str, chunks: list[AudioChunk], chunk_s: float = 0.02) -> None:
    """Publish ``chunks`` in real time (a monotonic schedule, a chunk's slot kept for a skipped seq)."""
    publisher = bus.stream_publisher(keys.audio(robot, "speaker"), AUDIO)
    try:
        start = time.monotonic()
        first = chunks[0].seq
        for chunk in chunks:
            time.sleep(max(0.0, start + (chunk.seq - first) * chunk_s - time.monotonic()))
            publisher.put(codec.encode(chunk.message()))
    finally:
        publisher.undeclare()


def played_when_done(device: ALAudioDevice, seconds: float) -> np.ndarray:
    """What the fake played once it holds ``seconds`` of sound and then nothing more for a while."""
    def settled() -> list[np.ndarray]:
        before = device.played()
        time.sleep(0.3)
        after = device.played()
        loud = np.flatnonzero(np.abs(after[:, 0]) > QUIET)
        done = len(after) == len(before) or (loud.size and len(after) - loud[-1] > OUT // 5)
        return [after] if loud.size and loud[-1] - loud[0] >= 0.9 * seconds * OUT and done else []
    return wait_for(settled, timeout=seconds + 10.0, what=f"{seconds} s played by the fake robot")[0]


def sounding(played: np.ndarray) -> np.ndarray:
    """Channel 0 from its first loud sample to its last."""
    loud = np.flatnonzero(np.abs(played[:, 0]) > QUIET)
    return played[loud[0]:loud[-1] + 1, 0].astype(np.int32)


def quiet_runs(signal: np.ndarray, at_least: int) -> list[tuple[int, int]]:
    """(start, length) of every run of ``at_least`` samples or more at or below ``QUIET``."""
    quiet = np.concatenate(([0], (np.abs(signal) <= QUIET).astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(quiet))
    return [(int(a), int(b - a)) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= at_least]


def dominant_hz(signal: np.ndarray, rate: int) -> float:
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(len(signal))))
    return float(np.fft.rfftfreq(len(signal), 1 / rate)[np.argmax(spectrum)])


def max_step(hz: float, amplitude: float) -> float:
    """The largest sample-to-sample step of a sine: anything much steeper is a click."""
    return amplitude * 2 * np.pi * hz / OUT


def speaker_rig(rig: Any, **options: Any) -> tuple[NaoqiRig, ALAudioDevice]:
    r = rig(**options)
    wait_for(lambda: r.adapter.audio_present, what="the adapter to find ALAudioDevice")
    return r, r.fake.services["ALAudioDevice"]


class MicChunks:
    """A subscriber of ``<robot>/audio/mic``: every chunk, checked by the gate as any node would."""

    def __init__(self, bus: Bus, robot: str) -> None:
        self.key = keys.audio(robot, "mic")
        self.subscriber, self.queue = bus.subscribe(self.key)
        self.gate = messages.Gate(bus.limits)
        self.chunks: list[AudioChunk] = []

    def poll(self) -> list[AudioChunk]:
        for key, payload in self.queue.drain(0):
            self.chunks.append(AudioChunk.of(self.gate.check(keys.Key.parse(key), payload)))
        return self.chunks

    def leave(self) -> None:
        self.subscriber.undeclare()


def rms(chunks: list[AudioChunk]) -> float:
    return float(np.sqrt(np.mean(np.concatenate([c.samples() for c in chunks]).astype(np.float64) ** 2)))


@pytest.fixture
def qi_client() -> Iterator[Any]:
    sessions: list[Any] = []

    def connect(url: str) -> Any:
        session = qi.Session()
        session.connect(url)
        sessions.append(session)
        return session

    yield connect
    for session in sessions:
        session.close()


# -- speaker -----------------------------------------------------------------------------------


@pytest.mark.realtime
def test_a_sine_on_the_speaker_key_is_played_at_its_frequency_without_gaps(rig, figure):
    # 250 ms of jitter buffer: the test's publisher shares a busy 2-core machine with the adapter
    r, device = speaker_rig(rig, speaker_latency_ms=250)
    seconds = 2.5
    play(r.bus, "pepper", sine_chunks(440.0, OUT, seconds))
    played = played_when_done(device, seconds)
    sound = sounding(played)
    assert abs(len(sound) - seconds * OUT) <= 0.02 * seconds * OUT, f"{len(sound)} frames of sound"
    assert quiet_runs(sound, OUT // 1000) == [], "silence inside steady input"
    assert abs(dominant_hz(sound, OUT) - 440.0) <= 1.0
    peak = int(np.abs(played).max())
    assert 0.24 * 32767 <= peak <= CEILING * 32767 + 1, f"peak {peak}: the ceiling scales, it does not clip"
    assert np.array_equal(played[:, 0], played[:, 1]), "mono goes to both channels"
    assert device.refused == 0 and 1 <= device.largest <= MAX_FRAMES
    stats = dict(r.adapter.stats.items())
    assert stats["speaker_gaps"] == 0 and stats["speaker_errors"] == 0 and stats["bad"] == 0
    figure("calls", device.calls)
    figure("largest call", device.largest, "frames")
    figure("underruns (1 is the end of the input)", stats["speaker_underruns"])


def test_an_underrun_plays_silence_without_a_click_and_the_sound_resumes(rig):
    r, device = speaker_rig(rig)  # the default 100 ms
    chunks = sine_chunks(440.0, OUT, 2.0)
    play(r.bus, "pepper", chunks[:50])
    time.sleep(0.4)  # the sender pauses: the buffer runs dry
    play(r.bus, "pepper", chunks[50:])
    played = played_when_done(device, 2.4)
    sound = sounding(played)
    pauses = [length for _, length in quiet_runs(sound, OUT // 100)]
    assert any(0.25 * OUT <= length <= 0.8 * OUT for length in pauses), f"quiet runs: {pauses}"
    steps = np.abs(np.diff(sound))
    assert steps.max() <= 1.5 * max_step(440.0, CEILING * 32767), f"a step of {steps.max()}: a click"
    assert r.adapter.stats["speaker_underruns"] >= 1


def test_a_lost_chunk_plays_as_silence_of_its_length(rig):
    r, device = speaker_rig(rig, speaker_latency_ms=250)
    play(r.bus, "pepper", sine_chunks(440.0, OUT, 1.5, skip=(40,)))
    sound = sounding(played_when_done(device, 1.5))
    runs = quiet_runs(sound, OUT // 1000)
    assert len(runs) == 1, f"quiet runs: {runs}"
    assert 0.4 * 960 <= runs[0][1] <= 1.6 * 960, f"{runs[0][1]} frames of silence for a 960-frame chunk"
    assert abs(runs[0][0] - 40 * 960) <= 960  # where the chunk was
    assert r.adapter.stats["speaker_gaps"] == 1


def test_chunks_of_another_rate_are_converted_to_the_robots_48_khz(rig):
    r, device = speaker_rig(rig, speaker_latency_ms=250)
    play(r.bus, "pepper", sine_chunks(1000.0, 16000, 1.5))
    sound = sounding(played_when_done(device, 1.5))
    assert abs(len(sound) - 1.5 * OUT) <= 0.03 * 1.5 * OUT
    assert abs(dominant_hz(sound, OUT) - 1000.0) <= 2.0
    assert quiet_runs(sound, OUT // 1000) == []


def test_a_call_that_times_out_is_one_warning_and_the_speaker_goes_on(rig, caplog):
    r, device = speaker_rig(rig, connect_timeout_s=5.0)  # the link outlives the speaker's 1 s call timeout
    streaming = threading.Thread(target=play, args=(r.bus, "pepper", sine_chunks(440.0, OUT, 4.0)), daemon=True)
    with caplog.at_level(logging.WARNING, logger="sonibus.bus.adapter"):
        streaming.start()
        wait_for(lambda: r.adapter.stats["speaker_calls"] >= 10, what="the speaker playing")
        r.fake.freeze()  # every call now hangs
        wait_for(lambda: r.adapter.stats["speaker_errors"] >= 1, what="a call to time out")
        r.fake.resume()
        calls = r.adapter.stats["speaker_calls"]
        wait_for(lambda: r.adapter.stats["speaker_calls"] > calls + 10, timeout=10.0, what="the speaker again")
        streaming.join(10.0)
    warnings = [rec.getMessage() for rec in caplog.records if "did not play a block" in rec.getMessage()]
    assert len(warnings) == 1 and "no answer within 1 s" in warnings[0] and "\n" not in warnings[0], warnings
    assert r.adapter.state == "running" and device.refused == 0


def test_the_fake_speaker_refuses_what_naoqi_refuses_and_writes_what_it_played(fakes, qi_client, tmp_path):
    fake = fakes(played_wav=str(tmp_path / "on-stop.wav"))
    device = qi_client(fake.url).service("ALAudioDevice")
    with pytest.raises(RuntimeError, match=r"nbOfFrames 16385 is not in \[1, 16384\]"):
        device.sendRemoteBufferToOutput(16385, bytes(16385 * 4))
    with pytest.raises(RuntimeError, match="a buffer of 8 bytes is not 10 frames of 16-bit stereo"):
        device.sendRemoteBufferToOutput(10, bytes(8))
    frames = np.array([[1, -1], [300, -300], [-32768, 32767]], np.int16)
    assert device.sendRemoteBufferToOutput(3, frames.astype("<i2").tobytes()) is True
    path = tmp_path / "played.wav"
    assert device.dumpPlayed(str(path)) == 3
    data, rate = soundfile.read(path, dtype="int16")
    assert rate == OUT and data.tolist() == frames.tolist()
    audio = fake.services["ALAudioDevice"]
    assert (audio.calls, audio.refused, audio.largest) == (3, 2, 3)
    fake.stop()  # played_wav: written on stop
    data, rate = soundfile.read(tmp_path / "on-stop.wav", dtype="int16")
    assert rate == OUT and data.tolist() == frames.tolist()


# -- microphones ---------------------------------------------------------------------------------


def test_microphones_flow_only_while_someone_listens(rig, figure):
    r = rig(fake={"clock_offset_s": -3600.0})  # a robot whose clock is an hour behind
    device: ALAudioDevice = r.fake.services["ALAudioDevice"]
    wait_for(lambda: r.adapter.audio_present, what="the adapter to find ALAudioDevice")
    info = robot_info(r.bus, "pepper")
    schemas.validate("robot_info", info)
    assert info["audio"] == {"mic": {"rate": 16000, "channels": 4}, "speaker": {"rate": OUT, "channels": 2}}
    time.sleep(0.5)  # connected, nobody listens: nothing subscribes ALAudioDevice
    assert device.listeners == {} and device.delivered == 0 and r.adapter.stats["mic_chunks"] == 0

    mic = MicChunks(r.bus, "pepper")
    chunks = wait_for(lambda: len(mic.poll()) >= 40 and mic.chunks, timeout=10.0, what="microphone chunks")
    assert len(device.listeners) == 1
    seqs = [c.seq for c in chunks]  # (AUDIO drops under congestion: a busy machine may lose one)
    assert seqs == sorted(set(seqs)) and len(seqs) >= 0.9 * (seqs[-1] - seqs[0] + 1), seqs
    for chunk in chunks:
        assert (chunk.rate, chunk.channels) == (16000, 4) and 1 <= chunk.frames <= 320
        schemas.validate("audio_chunk", {**chunk.message(), "pcm": "(bytes)"})
    times = np.array([c.t for c in chunks])
    assert np.all(np.diff(times) > 0) and abs(times[-1] - time.time()) < 1.0, "robot time mapped to wall clock"
    for before, after in itertools.pairwise(chunks):
        if after.seq == before.seq + 1:
            assert after.t - before.t == pytest.approx(before.frames / 16000, abs=0.05), "t advances by a chunk"
    assert robot_info(r.bus, "pepper")["naoqi"]["mic_clock"] == "robot"
    figure("latency of the newest chunk's first sample", time.time() - times[-1], "s")

    mic.leave()
    wait_for(lambda: device.listeners == {}, what="the adapter to unsubscribe once nobody listens")
    delivered = device.delivered
    time.sleep(0.5)
    assert device.delivered == delivered
    assert robot_info(r.bus, "pepper")["naoqi"]["mic_subscribed"] is False


def test_the_microphone_level_follows_a_commanded_joint_move(rig):
    r = rig()  # (not idle: the body rests until told to move)
    mic = MicChunks(r.bus, "pepper")
    wait_for(lambda: len(mic.poll()) >= 20, timeout=10.0, what="microphone chunks at rest")
    rest = rms(mic.chunks[-10:])
    mic.chunks.clear()
    assert send_command(r.bus, "pepper", "joints/set", {"names": ["HeadYaw", "HeadPitch"],
                                                        "angles": [1.5, -0.5], "speed": 0.6})["speed"] == 0.6
    wait_for(lambda: mic.poll() and rms(mic.chunks[-5:]) > 20 * max(rest, 1.0), timeout=5.0,
             what="the whine of the moving head", explain=lambda: f"rest rms {rest:.1f}")
    wait_for(lambda: not r.fake.engine.body.moving(), timeout=10.0, what="the head to stop")
    mic.chunks.clear()
    wait_for(lambda: len(mic.poll()) >= 20 and rms(mic.chunks[-10:]) < 3 * max(rest, 1.0), timeout=5.0,
             what="the level to fall at rest")


def test_microphones_come_back_after_the_link_is_replaced(net, fakes):
    """Wi-Fi drop: the link goes silent; on the new one the adapter subscribes a module of a new name."""
    robot = fakes()
    device: ALAudioDevice = robot.services["ALAudioDevice"]
    relay = Relay(int(robot.url.rsplit(":", 1)[1])).start()
    try:
        r = attach(net, relay.url(), connect_timeout_s=0.5, retry_max_s=0.5, fake=robot)
        mic = MicChunks(r.bus, "pepper")
        wait_for(lambda: mic.poll() and device.listeners, timeout=10.0, what="microphone chunks")
        first = set(device.listeners)
        relay.cut()
        r.events.wait("connection", timeout=5.0, state="lost")
        wait_for(lambda: r.events.find("connection", state="connected")[1:], timeout=10.0, what="connected again")
        count = len(mic.poll())
        wait_for(lambda: len(mic.poll()) > count + 20, timeout=10.0, what="microphone chunks on the new link")
        assert set(device.listeners) and not set(device.listeners) & first, "a module of a new name"
        seqs = [c.seq for c in mic.chunks]
        assert seqs == sorted(set(seqs)), "seq goes on across links"
    finally:
        relay.stop()


@pytest.mark.parametrize(("options", "fake"), [({"audio": False}, {}), ({}, {"audio": False})],
                         ids=["audio off", "no ALAudioDevice"])
def test_without_audio_the_info_says_none_and_nothing_is_subscribed(rig, options, fake):
    r = rig(fake=fake, **options)
    mic = MicChunks(r.bus, "pepper")
    time.sleep(1.0)
    assert "audio" not in robot_info(r.bus, "pepper") and not r.adapter.audio_present
    assert mic.poll() == [] and r.adapter.stats["mic_chunks"] == 0
    device = r.fake.services.get("ALAudioDevice")
    assert device is None or device.listeners == {}


# -- a frozen robot -----------------------------------------------------------------------------


def test_stop_is_bounded_while_streaming_to_a_frozen_robot(net, fake_process, figure):
    fake = fake_process()
    r = attach(net, fake.url, connect_timeout_s=5.0)
    wait_for(lambda: r.adapter.audio_present, what="the adapter to find ALAudioDevice")
    mic = MicChunks(r.bus, "pepper")
    wait_for(lambda: mic.poll(), timeout=10.0, what="microphone chunks")
    chunks = sine_chunks(440.0, OUT, 3.0)
    streaming = threading.Thread(target=play, args=(r.bus, "pepper", chunks), daemon=True)
    streaming.start()
    wait_for(lambda: r.adapter.stats["speaker_calls"] > 10, what="the speaker playing")
    fake.freeze()
    time.sleep(0.3)  # calls now hang on the robot
    started = time.monotonic()
    r.adapter.stop()
    elapsed = time.monotonic() - started
    figure("stop with the robot frozen, microphones subscribed and the speaker playing", elapsed, "s")
    assert elapsed <= EXIT_BOUND_S, f"stopped after {elapsed:.1f} s"
    assert r.adapter.state == "stopped"
    assert not [t.name for t in r.adapter._threads if t.is_alive()]
    streaming.join(5.0)


# -- options ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("key", "value", "says"), [
    ("volume_ceiling", 1.5, "must be in (0, 1]"),
    ("volume_ceiling", 0, "must be in (0, 1]"),
    ("speaker_latency_ms", 5, "must be in [10, 2000]"),
    ("mic_rate", 44100, "16000 or 48000"),
    ("mic_channels", "middle", "middle"),
])
def test_audio_options_are_checked(key, value, says):
    with pytest.raises(ConfigError) as error:
        from_mapping(NaoqiConfig, {key: value}, "show.toml [nodes.pepper]")
    message = str(error.value)
    assert key in message and says in message and "\n" not in message


def test_a_less_delayed_buffer_found_later_does_not_send_t_back():
    """The clock's offset is the least delayed buffer's: one arriving 50 ms sooner than the
    first moved t back by 50 ms, and chunk times went backwards (seen under load)."""
    from sonibus.adapters.naoqi.microphones import RobotClock
    clock = RobotClock()
    first = clock.start([100, 0], 0.17, arrived=1000.30)    # 130 ms late
    second = clock.start([100, 170000], 0.17, arrived=1000.42)  # 80 ms late: a smaller offset
    third = clock.start([100, 340000], 0.17, arrived=1000.59)
    assert first == pytest.approx(1000.13) and second - first >= 0.99 * 0.17 - 1e-9 <= third - second
    assert third == pytest.approx(second + 0.99 * 0.17)  # nearly contiguous, slewing toward the better offset


def test_a_robot_sound_clock_that_runs_fast_is_followed_not_run_ahead_of():
    """A buffer forced to start where the last one ended never came back: a robot whose
    sound clock runs 100 ppm fast put t 0.36 s an hour ahead, past the gate's 5 s in a day."""
    from sonibus.adapters.naoqi.microphones import RobotClock
    clock, duration, fast = RobotClock(), 0.17, 1.0001
    starts = [clock.start([n * duration * fast, 0], duration, arrived=1000.0 + (n + 1) * duration)
              for n in range(25_000)]                                    # 70 minutes of buffers
    steps = np.diff(starts)
    assert steps.min() > 0.98 * duration                                  # t never goes back
    assert abs(starts[-1] + duration - (1000.0 + 25_000 * duration)) < 0.01  # still on the wall clock
