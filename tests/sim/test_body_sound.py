"""The simulator's body sound: the servo whine itself (no bus), then the sim robot's
microphones and speaker over real Zenoh sessions (published only while anyone
listens, level following a joint move, the speaker playing what it is sent)."""

from __future__ import annotations

import itertools
import threading
import time
from typing import Any

import numpy as np
import pytest

from sonibus.adapters.sim.whine import Whine
from sonibus.bus import Bus, decode, robot_info, send_command
from sonibus.bus.audio import AudioChunk

from ..conftest import wait_for

MIC_KEY, SPEAKER_KEY = "pepper/audio/mic", "pepper/audio/speaker"


# -- helpers --------------------------------------------------------------------

def rms(samples: np.ndarray) -> float:
    return float(np.sqrt(np.mean(samples.astype(np.float64) ** 2)))


def peak_hz(samples: np.ndarray, rate: int) -> float:
    """The strongest frequency of the first channel (Hann window)."""
    mono = samples[:, 0].astype(np.float64)
    spectrum = np.abs(np.fft.rfft(mono * np.hanning(len(mono))))
    spectrum[0] = 0.0
    return float(np.argmax(spectrum) * rate / len(mono))


def render(whine: Whine, seconds: float, speeds: dict[str, float], block: int = 320) -> np.ndarray:
    return np.concatenate([whine.render(block, speeds) for _ in range(round(seconds * whine.rate / block))])


class Chunks:
    """Every mic chunk of the test's subscription, decoded, in arrival order."""

    def __init__(self, bus: Bus, keyexpr: str = MIC_KEY) -> None:
        self.subscriber, self.queue = bus.subscribe(keyexpr, maxlen=100_000)
        self.items: list[AudioChunk] = []

    def poll(self) -> list[AudioChunk]:
        while (item := self.queue.get(timeout=0)) is not None:
            self.items.append(AudioChunk.of(decode(item[1])))
        return self.items


def sine_chunks(hz: float, rate: int, channels: int, seconds: float, chunk_ms: float = 20.0,
                amplitude: float = 0.5) -> list[AudioChunk]:
    frames = round(rate * chunk_ms / 1000)
    count = round(seconds * 1000 / chunk_ms)
    n = np.arange(count * frames)
    wave = amplitude * np.sin(2 * np.pi * hz * n / rate)
    block = np.repeat(wave[:, None], channels, axis=1)
    return [AudioChunk.from_samples(time.time(), seq, rate, block[seq * frames:(seq + 1) * frames])
            for seq in range(count)]


def play(bus: Bus, chunks: list[AudioChunk], key: str = SPEAKER_KEY) -> None:
    """Publish ``chunks`` in real time (absolute deadlines), as a sound tool would."""
    start = time.monotonic()
    elapsed = 0.0
    for chunk in chunks:
        time.sleep(max(0.0, start + elapsed - time.monotonic()))
        bus.put(key, chunk.message())
        elapsed += chunk.duration


# -- the whine, no bus --------------------------------------------------------------

def test_the_whine_is_silent_at_rest_and_its_level_rises_with_speed():
    levels = []
    for speed in (0.0, 0.5, 1.5, 4.0):
        whine = Whine(16000, 1)
        levels.append(rms(render(whine, 0.5, {"HeadYaw": speed} if speed else {})[4000:]))
    assert levels[0] < 10, levels  # a faint noise floor (a few LSB) at most
    assert levels[0] * 20 < levels[1] < levels[2] < levels[3], levels


def test_the_level_is_relative_to_the_joints_max_speed():
    """1 rad/s is a larger share of a slow joint's speed: HipRoll (2.27 rad/s max) whines louder than
    HeadPitch (9.23 rad/s max) at the same speed."""
    hip = rms(render(Whine(16000, 1), 0.5, {"HipRoll": 1.0})[4000:])
    head = rms(render(Whine(16000, 1), 0.5, {"HeadPitch": 1.0})[4000:])
    assert hip > 2 * head, (hip, head)


def test_the_pitch_rises_with_speed():
    pitches = [peak_hz(render(Whine(16000, 1, grit=0.0), 1.0, {"HeadYaw": speed})[8000:], 16000)
               for speed in (0.5, 2.0, 5.0)]
    assert pitches[0] < pitches[1] < pitches[2], pitches
    assert 150 < pitches[0] < 400, pitches  # a buzz above BASE_HZ, not noise


def test_starting_and_stopping_make_no_click():
    whine = Whine(48000, 1, grit=0.0, floor=0.0)
    start = whine.render(4800, {"HeadYaw": 7.0})[:, 0].astype(np.int64)
    steady = whine.render(4800, {"HeadYaw": 7.0})[:, 0].astype(np.int64)
    stop = whine.render(9600, {})[:, 0].astype(np.int64)
    assert np.abs(start[:48]).max() < 0.1 * np.abs(steady).max()  # its first ms: a fade-in, not a step
    assert np.abs(np.diff(np.concatenate([steady, stop]))).max() <= np.abs(np.diff(steady)).max()  # no jump
    assert np.abs(stop[-480:]).max() < 0.01 * np.abs(steady).max()  # and it fades out


def test_phase_is_kept_across_calls_and_the_same_seed_gives_the_same_sound():
    speeds = {"HeadYaw": 2.0, "RShoulderPitch": 1.0}
    whole = Whine(16000, 2, grit=0.0, floor=0.0).render(640, speeds)
    split_whine = Whine(16000, 2, grit=0.0, floor=0.0)
    split = np.concatenate([split_whine.render(n, speeds) for n in (100, 220, 320)])
    assert np.abs(whole.astype(np.int32) - split).max() <= 1  # (rounding)
    first, second = Whine(16000, 1, seed=7), Whine(16000, 1, seed=7)
    assert all(np.array_equal(first.render(320, speeds), second.render(320, speeds)) for _ in range(5))
    assert not np.array_equal(Whine(16000, 1, seed=8).render(320, speeds), Whine(16000, 1, seed=7).render(320, speeds))


def test_the_whine_stays_in_range_with_every_joint_at_full_speed():
    whine = Whine(16000, 4)
    speeds = {name: spec.max_velocity for name, spec in zip(whine.model.joint_names, whine.model.joints,
                                                             strict=True)}
    out = render(whine, 0.5, speeds)
    assert out.dtype == np.int16 and out.shape == (8000, 4)
    assert np.abs(out.astype(np.int32)).max() <= 32767
    assert rms(out) > 1000


# -- the sim robot on the bus --------------------------------------------------------

def test_info_says_what_audio_the_sim_has(net):
    net.sim()
    client = net.bus("client")
    assert robot_info(client, "pepper")["audio"] == {"mic": {"rate": 16000, "channels": 1},
                                                     "speaker": {"rate": 48000, "channels": 2}}


def test_with_body_sound_and_speaker_off_there_is_no_audio(net):
    sim = net.sim(body_sound=False, speaker=False)
    client = net.bus("client")
    assert "audio" not in robot_info(client, "pepper")
    assert not [t for t in sim._threads if t.name.endswith((":mic", ":speaker"))]
    chunks = Chunks(client)
    send_command(client, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [1.0], "speed": 0.5})
    wait_for(lambda: not sim.engine.body.moving(), what="the move to end")
    assert chunks.poll() == [] and sim.stats["mic_chunks"] == 0


def test_the_mic_publishes_only_while_anyone_listens(net):
    sim = net.sim(idle=True)  # idling moves joints: there is something to hear
    client = net.bus("client")
    _frames = client.subscribe("pepper/frame")  # a subscriber of other keys is not a listener
    wait_for(lambda: sim.stats["speaker_frames"] >= 10 * 960, what="10 ticks of the speaker")
    assert sim.stats["mic_chunks"] == 0 and not sim.mic.listening

    chunks = Chunks(client)
    wait_for(lambda: len(chunks.poll()) >= 25, what="25 mic chunks")
    # Nothing lost: at some instant between two ticks, every chunk published was received (a
    # tick the sim's pacer skipped on a loaded machine is a gap in seq by design, not a loss).
    wait_for(lambda: len(chunks.poll()) == sim.stats["mic_chunks"], what="every chunk published, received")
    items = chunks.poll()
    assert [c.seq for c in items] == sorted({c.seq for c in items})  # in order, none twice
    assert {(c.rate, c.channels, c.frames) for c in items} == {(16000, 1, 320)}
    assert all(b.t > a.t for a, b in itertools.pairwise(items))

    chunks.subscriber.undeclare()
    wait_for(lambda: not sim.mic.listening, what="the sim to see nobody listens")
    sent = sim.stats["mic_chunks"]
    played = sim.stats["speaker_frames"]
    wait_for(lambda: sim.stats["speaker_frames"] >= played + 10 * 960, what="10 more ticks of the speaker")
    assert sim.stats["mic_chunks"] <= sent + 1  # (one chunk may have been under way)


def test_an_unheard_mic_waits_for_a_listener_instead_of_ticking(net):
    """Nobody listens: the mic's loop sleeps through its 20 ms ticks (waits for a listener,
    up to 0.2 s at a time) rather than waking for each; a listener gets chunks at once."""
    sim = net.sim(idle=True)
    client = net.bus("client")
    wait_for(lambda: sim.stats["speaker_frames"] > 0, what="the sim's audio running")
    skipped, started = sim.mic.pacer.skipped, time.monotonic()
    wait_for(lambda: time.monotonic() - started >= 1.0, what="a second")
    assert sim.mic.pacer.skipped - skipped >= 25  # (a tick per 20 ms: 50 a second, most of them slept through)
    chunks = Chunks(client)
    wait_for(lambda: len(chunks.poll()) >= 5, what="5 mic chunks once someone listens")


def test_the_mic_level_follows_a_joint_move(net):
    sim = net.sim()
    client = net.bus("client")
    chunks = Chunks(client)
    frames = client.subscribe("pepper/frame", maxlen=100_000)[1]
    wait_for(lambda: len(chunks.poll()) >= 15, what="300 ms of mic chunks at rest")
    send_command(client, "pepper", "joints/set", {"names": ["HeadYaw"], "angles": [-1.5], "speed": 0.2})
    wait_for(lambda: sim.engine.body.moving(["HeadYaw"]), what="the head to move")
    wait_for(lambda: not sim.engine.body.moving(["HeadYaw"]), timeout=10, what="the head to stop")
    stopped = time.time()
    wait_for(lambda: chunks.poll()[-1].t > stopped + 0.5, what="500 ms of mic chunks after the move")

    head = sim.model.joint_names.index("HeadYaw")
    poses = [(m["t"], m["v"][head]) for _key, payload in frames.drain(0) for m in [decode(payload)]]
    moving = [t for (t, v), (_t2, w) in itertools.pairwise(poses) if v != w]
    begin, end = moving[0], moving[-1]
    assert end - begin > 0.5  # (1.5 rad at 0.2 × 7.3 rad/s)

    def level(first: float, last: float) -> float:
        inside = [c.samples() for c in chunks.poll() if first <= c.t and c.t + c.duration <= last]
        assert len(inside) >= 5, (first, last, len(inside))
        return rms(np.concatenate(inside))

    before = level(chunks.items[0].t, begin - 0.1)
    during = level(begin + 0.15, end - 0.15)
    after = level(end + 0.3, chunks.items[-1].t + 1)
    assert during > 20 * max(before, after, 1.0), (before, during, after)


def test_the_speaker_plays_what_it_is_sent_in_real_time(net):
    sim = net.sim(speaker_latency_ms=60)
    client = net.bus("client")
    wait_for(lambda: sim.stats["speaker_frames"] > 0, what="the speaker to run")
    play(client, sine_chunks(440.0, 48000, 2, 1.5))
    wait_for(lambda: sim.speaker.buffer.stats["underruns"] >= 1, what="the speaker to run dry after the sine")
    played = np.concatenate(list(sim.speaker.played))
    loud = played[np.abs(played[:, 0].astype(np.int32)) > 0]
    assert len(loud) > 48000  # most of the 1.5 s
    assert peak_hz(played, 48000) == pytest.approx(440.0, abs=2.0)
    assert np.array_equal(played[:, 0], played[:, 1])
    assert sim.stats["speaker_frames"] >= len(played)
    assert sim.stats["speaker_frames"] % 960 == 0  # whole blocks of 20 ms at 48 kHz


def test_the_speaker_converts_the_rate_and_counts_a_bad_chunk(net):
    sim = net.sim()
    client = net.bus("client")
    bad: dict[str, Any] = {**sine_chunks(440.0, 16000, 1, 0.02)[0].message(), "rate": 7000}
    client.put(SPEAKER_KEY, bad)
    wait_for(lambda: sim.stats["bad"] >= 1, what="the bad chunk to be counted")
    play(client, sine_chunks(1000.0, 16000, 1, 1.0))
    wait_for(lambda: sim.speaker.buffer.stats["underruns"] >= 1, what="the speaker to run dry after the sine")
    assert peak_hz(np.concatenate(list(sim.speaker.played)), 48000) == pytest.approx(1000.0, abs=3.0)
    assert sim.stats["bad"] == 1


def test_stopping_the_sim_ends_its_audio_threads(net):
    sim = net.sim()
    client = net.bus("client")
    chunks = Chunks(client)
    wait_for(lambda: len(chunks.poll()) >= 3 and sim.stats["speaker_frames"] > 0, what="mic and speaker running")
    names = {t.name for t in sim._threads}
    assert {f"{sim.name}:mic", f"{sim.name}:speaker"} <= names
    sim.stop()
    assert [t.name for t in threading.enumerate() if t.name.startswith(f"{sim.name}:")] == []


def test_a_silent_speaker_waits_for_sound_instead_of_pulling_silence_every_tick(net):
    """Nothing to play: the speaker still counts its silence in real time, but in a few long
    blocks (it waits on its queue up to a second), not a 20 ms block per tick (50 a second) nor
    one per 0.2 s wait (5 a second: its thread 0.3 % of a core, issue 35); sound sent then plays
    at once."""
    sim = net.sim(speaker_latency_ms=60)
    client = net.bus("client")
    wait_for(lambda: sim.stats["speaker_frames"] > 0, what="the speaker to run")
    frames, blocks = sim.stats["speaker_frames"], len(sim.speaker.played)
    wait_for(lambda: sim.stats["speaker_frames"] >= frames + 48000, what="a second of silence played")
    ticks = len(sim.speaker.played) - blocks
    assert ticks <= 3, f"{ticks} blocks for a second of silence (a block per 20 ms tick: 50; per 0.2 s wait: 5)"
    play(client, sine_chunks(440.0, 48000, 2, 0.5))
    wait_for(lambda: sim.speaker.buffer.stats["underruns"] >= 1, what="the speaker to run dry after the sine")
    played = np.concatenate(list(sim.speaker.played))
    assert peak_hz(played, 48000) == pytest.approx(440.0, abs=4.0)
    assert sim.stats["speaker_frames"] % 960 == 0


def test_what_the_speaker_keeps_is_its_last_seconds_however_long_its_blocks(net):
    """``played`` keeps ``keep_s`` of sound by length: a silent speaker plays long blocks (up to
    a second after a wait), and a count of 20 ms blocks (500 for 10 s) kept 500 s of those."""
    from sonibus.adapters.sim.audio import SimSpeaker
    sim = net.sim(speaker=False, body_sound=False)
    speaker = SimSpeaker(sim, "pepper", 100.0, keep_s=0.5)  # (25 blocks of 20 ms)
    sim.spawn(speaker.run, "kept")
    try:
        wait_for(lambda: sim.stats.get("speaker_frames", 0) >= 2 * 48000, what="two seconds of silence played")
        blocks = list(speaker.played)
        newer = sum(len(block) for block in blocks[1:])  # (the oldest block kept is the one keep_s reaches into)
        assert newer < 24000, f"{newer / 48000:.2f} s kept after the oldest block, for keep_s 0.5"
    finally:
        speaker.close()  # (wakes it from its wait: the node's stop then ends it at once)
