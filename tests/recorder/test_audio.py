"""Audio in recordings: chunks on <robot>/audio/* are recorded (msgpack channels),
`sonibus export --wav` makes WAV files that keep time across a lost chunk, and
replay publishes the chunks again on their keys."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import soundfile
from mcap.reader import make_reader
from mcap.writer import Writer

from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.adapters.recorder.writer import RecordingWriter
from sonibus.bus import codec, keys
from sonibus.bus.audio import AudioChunk
from sonibus.bus.messages import Gate
from sonibus.bus.node import AUDIO

from ..conftest import run_cli, wait_for

MIC = (16000, 2, 320)     # rate, channels, frames of a chunk (20 ms)
SPEAKER = (48000, 1, 480)
LOST = {10, 11, 12}       # mic chunks that never reach the recorder
OTHER_RATE = 40           # a mic chunk at 48 kHz mono: skipped by the export, said once
CHUNKS = 45


def samples(seq: int, rate: int, channels: int, frames: int) -> np.ndarray:
    """A chunk's int16 samples, different in every chunk and channel."""
    n = np.arange(seq * frames, (seq + 1) * frames)
    columns = [np.sin(2 * np.pi * (300 + 200 * c) * n / rate) * (0.2 + 0.1 * c) for c in range(channels)]
    return np.rint(np.stack(columns, axis=1) * 32767).astype(np.int16)


def chunk(seq: int, stream: tuple[int, int, int], t0: float) -> AudioChunk:
    rate, channels, frames = stream
    return AudioChunk.from_samples(t0 + seq * frames / rate, seq, rate, samples(seq, rate, channels, frames))


def test_recorded_audio_exports_to_wav_with_its_rate_channels_and_length(net, tmp_path):
    path = tmp_path / "audio.mcap"
    recorder = net.start(Recorder(RecorderConfig(path=str(path), foxglove=False, subscribe=("*/audio/*",)),
                                  name="logger"))
    robot = net.bus("robot")
    mic = robot.stream_publisher(keys.audio("pepper", "mic"), AUDIO)
    speaker = robot.stream_publisher(keys.audio("pepper", "speaker"), AUDIO)
    heard = threading.Event()
    watch = robot.watch_subscribers("pepper/audio/*", lambda matching: matching and heard.set())
    wait_for(heard.is_set, what="the recorder's subscription")
    watch.undeclare()
    t0 = time.time()
    sent = 0
    for seq in range(CHUNKS):
        if seq in LOST:
            continue
        if seq == OTHER_RATE:
            odd = AudioChunk.from_samples(t0 + seq * 0.02, seq, 48000, samples(seq, 48000, 1, 960))
            mic.put(codec.encode(odd.message()))
        else:
            mic.put(codec.encode(chunk(seq, MIC, t0).message()))
        sent += 1
        if seq < 5:
            speaker.put(codec.encode(chunk(seq, SPEAKER, t0).message()))
            sent += 1
        wait_for(lambda n=sent: recorder.stats["written"] >= n, what=f"chunk {seq} written")  # (drop QoS: one by one)
    recorder.stop()

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    channels = {c.topic: (c.message_encoding, summary.schemas[c.schema_id].name) for c in summary.channels.values()}
    assert channels["pepper/audio/mic"] == ("msgpack", "sonibus.v1.audio_chunk")
    info = run_cli("info", str(path))
    assert info.returncode == 0 and "pepper/audio/mic" in info.stdout and "pepper/audio/speaker" in info.stdout

    out = tmp_path / "wav"
    exported = run_cli("export", str(path), "--wav", str(out))
    assert exported.returncode == 0, exported.stderr
    assert "pepper/audio/mic: 1 chunk skipped: 48000 Hz × 1, not the 16000 Hz × 2" in exported.stdout
    mic_wav, rate = soundfile.read(out / "pepper-mic.wav", dtype="int16", always_2d=True)
    assert rate == 16000 and mic_wav.shape == (CHUNKS * 320, 2)  # the lost and the skipped chunks as silence
    for seq in range(CHUNKS):
        part = mic_wav[seq * 320:(seq + 1) * 320]
        if seq in LOST or seq == OTHER_RATE:
            assert not part.any(), f"chunk {seq}: not silent"
        else:
            assert (part == samples(seq, *MIC)).all(), f"chunk {seq}: not as recorded"
    speaker_wav, rate = soundfile.read(out / "pepper-speaker.wav", dtype="int16", always_2d=True)
    assert rate == 48000 and speaker_wav.shape == (5 * 480, 1)


def test_replay_publishes_the_audio_again_on_its_keys(net, tmp_path):
    path = tmp_path / "take.mcap"
    t0 = time.time() - 60
    with RecordingWriter(str(path)) as out:
        for seq in range(25):
            sent = chunk(seq, MIC, t0)
            out.write("pepper/audio/mic", int((sent.t + 0.005) * 1e9), sent.message())
    listener = net.bus("listener")
    subscriber, queue = listener.subscribe("pepper/audio/mic", maxlen=1024)
    replay = net.start(Replay(ReplayConfig(path=str(path)), name="replay"))
    wait_for(replay.finished.is_set, timeout=20, what="the replay's end")
    gate, got = Gate(), []
    wait_for(lambda: (got.extend(AudioChunk.of(gate.check(keys.Key.parse(k), p)) for k, p in queue.drain(0)) or
                      len(got) + replay.stats["late"] >= 25), what="every chunk replayed or skipped as late")
    subscriber.undeclare()
    assert len(got) >= 1 and replay.stats["late"] + len(got) == 25
    seqs = [c.seq for c in got]
    assert seqs == sorted(seqs)
    for received in got:  # the recorded PCM, its seq, moved to now with the recording's spacing
        assert received.pcm == chunk(received.seq, MIC, t0).pcm
        assert (received.rate, received.channels) == MIC[:2]
        assert abs(received.t - time.time()) < 30
    steps = np.diff([c.t for c in got]) / np.diff(seqs)
    assert np.allclose(steps, 0.02, rtol=0, atol=1e-5)  # (t near 1.7e9: float steps of 2.4e-7)


def test_export_says_when_there_is_no_audio_and_needs_a_format(tmp_path):
    path = tmp_path / "joints.mcap"
    with RecordingWriter(str(path)) as out:
        out.write("pepper/joints/HeadYaw", time.time_ns(), {"t": time.time(), "seq": 0, "v": 0.1})
    exported = run_cli("export", str(path), "--wav", str(tmp_path / "wav"))
    assert exported.returncode == 0 and f"no audio in {path}: no WAV written" in exported.stdout
    assert not (tmp_path / "wav").exists()
    neither = run_cli("export", str(path))
    assert neither.returncode == 2 and neither.stderr.startswith("sonibus: error: ")
    assert len(neither.stderr.splitlines()) == 1 and "--csv DIR" in neither.stderr and "--wav DIR" in neither.stderr


def test_export_leaves_out_what_is_no_audio_chunk_in_one_line(tmp_path):
    path = tmp_path / "foreign.mcap"  # (sonibus's recorder gate-checks what it writes; this file was made elsewhere)
    t0 = time.time() - 60
    with RecordingWriter(str(path)) as out:
        for seq in range(3):
            good = chunk(seq, MIC, t0)
            out.write("pepper/audio/mic", int(good.t * 1e9), good.message())
            if seq == 1:  # a cut-short chunk: half a frame more
                out.write("pepper/audio/mic", int(good.t * 1e9) + 1, {**good.message(), "pcm": good.pcm + b"\1\0"})
        out.write("pepper/audio/speaker", int(t0 * 1e9), {"t": t0, "seq": 0, "rate": 48000, "channels": 0,
                                                          "pcm": b"\1\0"})
    exported = run_cli("export", str(path), "--wav", str(tmp_path / "wav"))
    assert exported.returncode == 0, exported.stderr
    assert exported.stderr == f"sonibus: WARNING: {path}: skipped 2 messages (the first: pepper/audio/mic: pcm of " \
                              "1282 bytes is not a whole number of 2-channel int16 frames (4 bytes each, 1 at least))\n"
    mic_wav, rate = soundfile.read(tmp_path / "wav" / "pepper-mic.wav", dtype="int16", always_2d=True)
    assert rate == 16000 and mic_wav.shape == (3 * 320, 2)
    assert (mic_wav[320:640] == samples(1, *MIC)).all()
    assert not (tmp_path / "wav" / "pepper-speaker.wav").exists()  # nothing to write: no file


def test_export_leaves_out_an_audio_key_written_as_json_with_a_number_msgpack_cannot_hold(tmp_path):
    path = tmp_path / "json.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="elsewhere")
        channel = writer.register_channel("pepper/audio/mic", "json", 0)
        message = {"t": time.time() - 60, "seq": 2**70, "rate": 16000, "channels": 1, "pcm": "AAA="}
        writer.add_message(channel, log_time=time.time_ns(), publish_time=time.time_ns(),
                           data=json.dumps(message).encode())
        writer.finish()
    exported = run_cli("export", str(path), "--wav", str(tmp_path / "wav"))
    assert exported.returncode == 0, exported.stderr
    assert "skipped 1 message (the first: pepper/audio/mic: " in exported.stderr, exported.stderr
    assert len(exported.stderr.splitlines()) == 1, exported.stderr
    assert not (tmp_path / "wav" / "pepper-mic.wav").exists()


def test_replay_faster_or_slower_leaves_audio_out_in_one_warning(net, tmp_path, caplog):
    """At --speed 2 the chunks went out twice as often: every player overran."""
    path = tmp_path / "take.mcap"
    t0 = time.time() - 60
    with RecordingWriter(str(path)) as out:
        for seq in range(10):
            sent = chunk(seq, MIC, t0)
            out.write("pepper/audio/mic", int((sent.t + 0.005) * 1e9), sent.message())
            out.write("pepper/events/status", int((sent.t + 0.005) * 1e9), {"t": sent.t, "kind": "status", "n": seq})
    listener = net.bus("listener")
    subscriber, queue = listener.subscribe("pepper/**", maxlen=1024)
    replay = net.start(Replay(ReplayConfig(path=str(path), speed=2.0), name="replay"))
    wait_for(replay.finished.is_set, timeout=20, what="the replay's end")
    seen: list[str] = []
    wait_for(lambda: seen.extend(k for k, _ in queue.drain(0.2)) or seen.count("pepper/events/status") >= 1,
             what="an event replayed")
    subscriber.undeclare()
    assert "pepper/audio/mic" not in replay.keys and "pepper/audio/mic" not in seen, seen
    warned = [r.getMessage() for r in caplog.records if "audio left out" in r.getMessage()]
    assert len(warned) == 1 and "--speed 2: audio left out (pepper/audio/mic)" in warned[0], warned
