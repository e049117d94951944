"""The jitter buffer, pushed and pulled by hand (no threads, no clocks but the
smoke test's): what plays, what is silent, what is dropped, and no clicks."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from sonibus.bus.audio import AudioChunk
from sonibus.bus.jitter import FADE_S, JitterBuffer

FADE = round(48000 * FADE_S)  # frames of a fade at 48 kHz


def sine(freq: float, rate: int, frames: int, amplitude: float = 0.5, channels: int = 1) -> np.ndarray:
    """int16 samples, shape (frames, channels)."""
    wave = amplitude * np.sin(2 * np.pi * freq * np.arange(frames) / rate)
    return AudioChunk.from_samples(0.0, 0, rate, np.repeat(wave[:, None], channels, axis=1)).samples()


def chunks(samples: np.ndarray, rate: int, size: int, seq: int = 0, t: float = 1000.0) -> list[AudioChunk]:
    return [AudioChunk.from_samples(t + i / rate, seq + n, rate, samples[i:i + size])
            for n, i in enumerate(range(0, len(samples), size))]


def largest_step(out: np.ndarray) -> int:
    return int(np.abs(np.diff(out.astype(np.int32), axis=0)).max())


def test_playback_starts_once_the_target_is_buffered():
    buffer = JitterBuffer(48000, 1, target_ms=100)
    pieces = chunks(sine(440, 48000, 4800), 48000, 480)
    for chunk in pieces[:-1]:
        buffer.push(chunk)
        assert not buffer.pull(0).size
    assert not buffer.pull(480).any() and buffer.stats["played_frames"] == 0    # 90 ms: still silent
    buffer.push(pieces[-1])
    assert buffer.pull(480).any() and buffer.stats["played_frames"] == 480


def test_a_sine_comes_out_sample_for_sample_after_its_fade_in():
    buffer = JitterBuffer(48000, 2, target_ms=100)
    signal = sine(440, 48000, 48000, channels=2)
    out = []
    for n, chunk in enumerate(chunks(signal, 48000, 480)):
        buffer.push(chunk)
        if n >= 9:
            out.append(buffer.pull(480))
    out = np.concatenate(out)
    assert out.dtype == np.int16 and out.shape == (len(signal) - 9 * 480, 2)
    assert np.array_equal(out[FADE:], signal[FADE:len(out)])
    assert (np.abs(out[:FADE]) <= np.abs(signal[:FADE])).all()                  # faded in, not cut in
    assert buffer.stats == {"underruns": 0, "overruns": 0, "gaps": 0, "refused": 0, "played_frames": len(out)}


def test_a_sine_resampled_from_16_to_48_khz_keeps_its_frequency_and_has_no_seams(figure):
    buffer = JitterBuffer(48000, 2, target_ms=100, follow_drift=0)  # (twice its target buffered: it would follow)
    signal = sine(1000, 16000, 32000, amplitude=0.5, channels=1)               # 2 s of one microphone
    out = []
    for n, chunk in enumerate(chunks(signal, 16000, 320)):                      # 20 ms chunks
        buffer.push(chunk)
        if n >= 10:
            out.append(buffer.pull(960))
    out = np.concatenate(out)
    assert buffer.stats["underruns"] == 0 and buffer.stats["overruns"] == 0
    held = 3 * len(signal) - buffer.stats["played_frames"] - buffer.buffered     # still inside soxr
    figure("held by the 16 -> 48 kHz resampler", 1000 * held / 48000, "ms")
    steady = out[4800:].astype(np.float64)                                      # past the fade-in
    assert np.array_equal(steady[:, 0], steady[:, 1])                           # one microphone on both sides
    spectrum = np.abs(np.fft.rfft(steady[:, 0] * np.hanning(len(steady))))
    peak = np.fft.rfftfreq(len(steady), 1 / 48000)[spectrum.argmax()]
    assert abs(peak - 1000) < 2 * 48000 / len(steady), peak
    natural = 0.5 * 32767 * 2 * np.pi * 1000 / 48000                             # a sine's largest step
    assert largest_step(steady) <= 1.1 * natural                                # no seam between chunks
    assert 0.45 * 32767 < np.abs(steady).max() <= 0.55 * 32767                  # the level kept


def test_running_dry_fades_out_to_silence_and_back_in_without_a_click():
    buffer = JitterBuffer(48000, 1, target_ms=100)
    signal = sine(442.5, 48000, 9600, amplitude=0.8)                              # its 4800th frame is a peak
    assert abs(int(signal[4799, 0])) > 0.79 * 32767
    bound = 0.8 * 32767 * (2 * np.pi * 442.5 / 48000 + 1 / FADE) * 1.1          # the sine's step + a fade's
    pieces = chunks(signal, 48000, 480)
    for chunk in pieces[:10]:
        buffer.push(chunk)
    out = buffer.pull(6000)                                                     # 100 ms buffered, 125 asked
    assert buffer.stats["underruns"] == 1 and buffer.stats["played_frames"] == 4800
    assert np.array_equal(out[FADE:4800 - FADE], signal[FADE:4800 - FADE])
    assert not out[4799:].any()                                                 # silence after the fade-out
    assert largest_step(out) <= bound
    for chunk in pieces[10:]:
        buffer.push(chunk)
    back = buffer.pull(4800)
    assert buffer.stats["underruns"] == 1
    assert largest_step(np.concatenate([out, back])) <= bound                   # faded back in
    assert np.array_equal(back[FADE:], signal[4800 + FADE:])


def test_running_dry_with_too_little_left_to_fade_ramps_down_from_the_last_frame():
    buffer = JitterBuffer(48000, 1, target_ms=100)
    signal = sine(442.5, 48000, 4800, amplitude=0.8)
    for chunk in chunks(signal, 48000, 480):
        buffer.push(chunk)
    out = [buffer.pull(4790), buffer.pull(20), buffer.pull(7), buffer.pull(480)]  # 10 frames left at a peak
    joined = np.concatenate(out)
    assert buffer.stats["underruns"] == 1 and abs(int(joined[4799, 0])) > 0.79 * 32767
    assert largest_step(joined) <= 0.8 * 32767 * (2 * np.pi * 442.5 / 48000 + 1 / FADE) * 1.1
    assert joined[4800:4800 + FADE - 1].all() and not joined[4800 + FADE:].any()   # the ramp, then silence


def test_a_fade_out_cut_short_by_a_small_pull_finishes_before_playback_starts_again():
    buffer = JitterBuffer(48000, 1, target_ms=10)
    signal = sine(442.5, 48000, 1440, amplitude=0.8)
    pieces = chunks(signal, 48000, 480)
    buffer.push(pieces[0])
    out = [buffer.pull(475), buffer.pull(7)]                                     # dry 2 frames into the ramp
    buffer.push(pieces[1])
    out += [buffer.pull(480), buffer.pull(480), buffer.pull(480)]              # again, and dry again
    joined = np.concatenate(out)
    assert buffer.stats["underruns"] == 2 and buffer.stats["played_frames"] == 960
    assert largest_step(joined) <= 0.8 * 32767 * (2 * np.pi * 442.5 / 48000 + 1 / FADE) * 1.1
    assert not joined[-480:].any()                                              # silence at the end


def test_an_overrun_drops_the_oldest_so_the_newest_plays():
    buffer = JitterBuffer(48000, 1, target_ms=20, max_ms=60)
    signal = sine(440, 48000, 4800)
    for chunk in chunks(signal, 48000, 480):                                     # 100 ms, none pulled
        buffer.push(chunk)
    assert buffer.stats["overruns"] == 2400 and buffer.buffered == 2400         # cut to 20 ms at 70 ms, +30 ms
    out = buffer.pull(2400)
    assert np.array_equal(out[FADE:], signal[-2400 + FADE:])                   # the newest 50 ms


def test_an_overrun_while_playing_crossfades_into_the_newest_without_a_click():
    buffer = JitterBuffer(48000, 1, target_ms=20, max_ms=60)
    signal = sine(300, 48000, 4800, amplitude=0.8)
    pieces = chunks(signal, 48000, 480)
    for chunk in pieces[:2]:
        buffer.push(chunk)
    played = buffer.pull(700)
    for chunk in pieces[2:]:                                                   # 80 ms more, none pulled
        buffer.push(chunk)
    assert buffer.stats["overruns"] > 0
    rest = buffer.pull(buffer.buffered)
    assert np.array_equal(rest[-480:], signal[-480:])                          # the newest plays
    out = np.concatenate([played, rest])
    assert largest_step(out) <= 0.8 * 32767 * (2 * np.pi * 300 / 48000 + 1 / FADE) * 1.1


def test_a_missing_chunk_plays_as_silence_of_its_length():
    buffer = JitterBuffer(48000, 1, target_ms=100)
    signal = sine(442.5, 48000, 7200, amplitude=0.8)
    pieces = chunks(signal, 48000, 480)
    for chunk in pieces[:10] + pieces[11:]:                                     # seq 10 lost
        buffer.push(chunk)
    out = buffer.pull(7200)
    assert buffer.stats["gaps"] == 1 and buffer.stats["played_frames"] == 7200 and buffer.stats["underruns"] == 0
    assert not out[4800:5280].any()                                            # where seq 10 would have played
    assert np.array_equal(out[FADE:4800 - FADE], signal[FADE:4800 - FADE])
    assert np.array_equal(out[5280 + FADE:], signal[5280 + FADE:])              # then it goes on in time
    assert largest_step(out) <= 0.8 * 32767 * (2 * np.pi * 442.5 / 48000 + 1 / FADE) * 1.1


def test_a_lost_chunk_while_a_fade_out_is_under_way_does_not_fade_out_a_second_time():
    buffer = JitterBuffer(48000, 1, target_ms=10)
    pieces = chunks(sine(442.5, 48000, 1440, amplitude=0.8), 48000, 480)
    buffer.push(pieces[0])
    out = [buffer.pull(475), buffer.pull(7)]                                     # dry 2 frames into the ramp
    buffer.push(pieces[2])                                                      # seq 1 lost
    out += [buffer.pull(480) for _ in range(4)]
    joined = np.concatenate(out)
    assert buffer.stats["gaps"] == 1 and buffer.stats["played_frames"] == 480 + 480 + 480
    assert largest_step(joined) <= 0.8 * 32767 * (2 * np.pi * 442.5 / 48000 + 1 / FADE) * 1.1


def test_a_lost_chunk_of_a_resampled_stream_fades_out_without_the_resampler_ringing():
    buffer = JitterBuffer(48000, 1, target_ms=20)
    pieces = chunks(sine(442.5, 44100, 441 * 12, amplitude=0.8), 44100, 441)
    out = []
    for n, chunk in enumerate(pieces):
        if n != 4:                                                              # seq 4 lost
            buffer.push(chunk)
        out.append(buffer.pull(960))
    assert buffer.stats["gaps"] == 1
    assert largest_step(np.concatenate(out)) <= 0.8 * 32767 * (2 * np.pi * 442.5 / 48000 + 1 / FADE) * 1.1


def test_a_jump_of_seq_counts_no_more_missing_chunks_than_the_buffer_could_hold():
    buffer = JitterBuffer(48000, 1, target_ms=20, max_ms=60)
    pieces = chunks(sine(440, 48000, 960), 48000, 480)
    buffer.push(pieces[0])
    buffer.push(AudioChunk(pieces[1].t, 2**62, 48000, 1, pieces[1].pcm))        # one chunk, seq far ahead
    assert 0 < buffer.stats["gaps"] <= 60 / 10 + 1 and buffer.buffered == buffer.target
    assert buffer.pull(buffer.buffered)[-480 + FADE:].any()                    # the chunk still plays


def test_a_chunk_whose_seq_goes_back_is_dropped_but_a_restarted_sender_is_heard():
    buffer = JitterBuffer(48000, 1, target_ms=20)
    pieces = chunks(sine(440, 48000, 1440), 48000, 480)
    for chunk in pieces:
        buffer.push(chunk)
    buffer.push(pieces[1])                                                      # late: seq and t behind
    assert buffer.stats["refused"] == 1 and buffer.buffered == 1440
    restarted = chunks(sine(440, 48000, 480), 48000, 480, seq=0, t=2000.0)[0]
    buffer.push(restarted)                                                      # seq behind, t ahead
    assert buffer.stats["refused"] == 1 and buffer.stats["gaps"] == 0 and buffer.buffered == 1920


def test_a_restarted_sender_is_faded_in_after_the_old_stream_without_a_click():
    buffer = JitterBuffer(48000, 1, target_ms=20)
    old = chunks(sine(442.5, 48000, 3360, amplitude=0.8), 48000, 480)
    new = chunks(-sine(442.5, 48000, 4800, amplitude=0.8)[::-1].copy(), 48000, 480, seq=0, t=2000.0)  # not at 0
    out = []
    for chunk in old + new:                                                     # seq back to 0, t ahead
        buffer.push(chunk)
        out.append(buffer.pull(480))
    out.append(buffer.pull(buffer.buffered))
    assert buffer.stats["refused"] == 0 and buffer.stats["played_frames"] == 3360 + 4800
    assert largest_step(np.concatenate(out)) <= 0.8 * 32767 * (2 * np.pi * 442.5 / 48000 + 1 / FADE) * 1.1


def test_a_lost_chunk_of_a_resampled_stream_keeps_time():
    buffer = JitterBuffer(48000, 1, target_ms=100)
    pieces = chunks(sine(442.5, 16000, 16000, amplitude=0.8), 16000, 320)
    for n, chunk in enumerate(pieces):
        if n != 20:                                                             # seq 20 lost
            buffer.push(chunk)
    whole = JitterBuffer(48000, 1, target_ms=100)
    for chunk in pieces:
        whole.push(chunk)
    assert buffer.stats["gaps"] == 1 and buffer.buffered == whole.buffered     # silence for all it did not play


def test_a_sender_that_changes_its_rate_is_converted_on_without_a_break():
    buffer = JitterBuffer(48000, 1, target_ms=100)
    first = chunks(sine(500, 48000, 24000, amplitude=0.5), 48000, 960)          # 0.5 s at 48 kHz, then
    then = chunks(sine(500, 16000, 16000, amplitude=0.5), 16000, 320, seq=len(first))  # 1 s at 16 kHz
    out = []
    for n, chunk in enumerate(first + then):
        buffer.push(chunk)
        if n >= 5:
            out.append(buffer.pull(960))
    out = np.concatenate(out)
    assert buffer.stats["underruns"] == 0 and buffer.stats["gaps"] == 0 and buffer.stats["refused"] == 0
    late = out[len(out) // 2:].astype(np.float64)                               # well into the 16 kHz part
    spectrum = np.abs(np.fft.rfft(late[:, 0] * np.hanning(len(late))))
    assert abs(np.fft.rfftfreq(len(late), 1 / 48000)[spectrum.argmax()] - 500) < 2 * 48000 / len(late)
    quiet = np.abs(out[FADE:FADE + (len(out) - FADE) // 96 * 96, 0]) < 10
    assert not quiet.reshape(-1, 96).all(axis=1).any()                          # no 2 ms of silence anywhere


def test_the_ceiling_holds_for_full_scale_input_even_through_resampling():
    square = np.where(np.sin(2 * np.pi * 300 * np.arange(4410) / 44100) >= 0, 32767, -32768).astype(np.int16)
    for ceiling in (1.0, 0.5, 0.1):
        buffer = JitterBuffer(48000, 2, target_ms=20, ceiling=ceiling)
        out = []
        for chunk in chunks(square[:, None], 44100, 441):                      # Gibbs overshoot past full scale
            buffer.push(chunk)
            out.append(buffer.pull(480))
        out = np.concatenate(out).astype(np.int32)
        limit = int(32767 * ceiling)
        assert np.abs(out).max() == limit, ceiling                              # reached, never passed
    same_rate = JitterBuffer(48000, 1, target_ms=10, ceiling=0.25)
    same_rate.push(AudioChunk.from_samples(1.0, 0, 48000, np.full((480, 1), -32768, np.int16)))
    assert same_rate.pull(480)[FADE:].tolist() == [[-8191]] * (480 - FADE)     # scaled: a volume, not a clip


def test_channels_are_mixed_down_by_the_mean_and_up_by_copying():
    down = JitterBuffer(8000, 1, target_ms=10)
    down.push(AudioChunk.from_samples(1.0, 0, 8000, np.tile([0.4, 0.2, 0.0, -0.2], (160, 1))))
    assert down.pull(160)[-1].tolist() == [round(0.1 * 32767)]
    up = JitterBuffer(8000, 3, target_ms=10)
    up.push(AudioChunk.from_samples(1.0, 0, 8000, np.full((160, 1), 0.25)))
    assert up.pull(160)[-1].tolist() == [8192] * 3


@pytest.mark.parametrize(("options", "reason"), [
    ({"rate": 0}, "jitter buffer rate = 0: expected a positive integer, in Hz"),
    ({"channels": 9}, "jitter buffer channels = 9: expected an integer in 1..8"),
    ({"target_ms": 0}, "jitter buffer target_ms = 0: expected a positive number of ms"),
    ({"target_ms": 100, "max_ms": 50}, "jitter buffer max_ms = 50: expected more than target_ms (100)"),
    ({"ceiling": 1.5}, "jitter buffer ceiling = 1.5: expected a fraction of full scale in (0, 1]"),
])
def test_a_bad_setting_is_refused_in_one_line(options, reason):
    with pytest.raises(ValueError) as caught:
        JitterBuffer(**{"rate": 48000, "channels": 2, **options})
    assert str(caught.value) == reason


def test_a_pushing_thread_and_a_pulling_one_lose_no_frame_unaccounted():
    buffer = JitterBuffer(48000, 2, target_ms=10, max_ms=30)
    signal = sine(440, 48000, 480 * 300, channels=2)
    pieces = chunks(signal, 48000, 480)
    pusher = threading.Thread(target=lambda: [buffer.push(chunk) for chunk in pieces])
    pusher.start()
    deadline = time.monotonic() + 30
    try:
        while pusher.is_alive():
            assert buffer.pull(256).shape == (256, 2)
            assert time.monotonic() < deadline, "the pusher never finished"
    finally:
        pusher.join(30)
    stats = buffer.stats
    assert stats["played_frames"] + stats["overruns"] + buffer.buffered == len(signal), (stats, buffer.buffered)
    assert stats["gaps"] == 0 and stats["refused"] == 0


def _two_clocks(drift: float, follow_drift: float, seconds: float = 120.0) -> tuple[JitterBuffer, np.ndarray]:
    """A sender whose clock runs ``drift`` off the player's (0.002: 0.2 % faster), 20 ms
    chunks of a 440 Hz sine at 8 kHz, played 20 ms at a time for ``seconds``."""
    rate, size = 8000, 160
    buffer = JitterBuffer(rate, 1, target_ms=100, follow_drift=follow_drift)
    pieces = chunks(sine(440, rate, round(rate * seconds * 1.01) + size), rate, size)
    sent, due, out = 0, 5.0, []          # (five chunks up front: the buffer's target)
    for _ in range(round(seconds * rate / size)):
        due += 1 + drift
        while sent < due:
            buffer.push(pieces[sent])
            sent += 1
        out.append(buffer.pull(size))
    return buffer, np.concatenate(out)


@pytest.mark.parametrize("drift", [-0.002, 0.002])
def test_two_clocks_apart_run_dry_or_over_unless_the_buffer_follows_the_drift(drift):
    """Two sound clocks are never one: 0.2 % apart (a dummy JACK beside wall-clock pacing;
    real cards are ~0.01 %), a fixed 100 ms buffer runs dry (or over) within a minute."""
    fixed, _ = _two_clocks(drift, follow_drift=0)
    assert fixed.stats["underruns" if drift < 0 else "overruns"] > 0, fixed.stats
    following, out = _two_clocks(drift, follow_drift=0.005)
    assert following.stats["underruns"] == following.stats["overruns"] == 0, following.stats
    assert following.ratio == pytest.approx(1 + drift, abs=0.0015)      # it plays at the sender's pace
    assert 0.2 * following.target < following.buffered < 2 * following.target  # (measured after a pull)
    natural = 0.5 * 32767 * 2 * np.pi * 440 / 8000 * 1.05                 # a sine's largest step, a little faster
    assert largest_step(out[800:]) <= 1.1 * natural                       # no click where it reads between frames
    steady = out[-80000:].astype(np.float64)                              # the last 10 s
    peak = np.fft.rfftfreq(len(steady), 1 / 8000)[np.abs(np.fft.rfft(steady[:, 0] * np.hanning(len(steady)))).argmax()]
    assert abs(peak - 440 * (1 + drift)) < 0.3, peak                      # pitch moved by the drift only


def test_a_stream_at_the_players_rate_is_never_resampled():
    buffer, out = _two_clocks(0.0, follow_drift=0.005, seconds=30)
    assert buffer.ratio == 1.0 and buffer.stats["underruns"] == buffer.stats["overruns"] == 0
    assert np.array_equal(out[800:1600], sine(440, 8000, 1600)[:800])  # sample for sample, past the fade-in
