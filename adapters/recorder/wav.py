"""WAV export of a recording's audio: one file per audio key, ``<robot>-<stream>.wav``.

Samples are written as recorded (int16, at the rate and channel count of the
key's first chunk). A gap in ``seq`` (chunks lost on the way, or dropped by
the recorder) becomes silence of the missing chunks' length, so the file keeps
time; a ``seq`` that goes back (the publisher restarted) is played on as it
comes. A chunk of another rate or channel count than the first is skipped, and
said once per file.

>>> import os, tempfile
>>> import numpy as np
>>> from sonibus.adapters.recorder.reading import Recording
>>> from sonibus.adapters.recorder.writer import RecordingWriter
>>> from sonibus.bus.audio import AudioChunk
>>> folder = tempfile.mkdtemp()
>>> with RecordingWriter(os.path.join(folder, "doc.mcap")) as out:
...     for seq in (0, 1, 3):  # chunk 2 was lost
...         chunk = AudioChunk.from_samples(1.7e9 + seq / 100, seq, 16000, np.full((160, 1), 0.5))
...         out.write("pepper/audio/mic", int(chunk.t * 1e9), chunk.message())
>>> with Recording(os.path.join(folder, "doc.mcap")) as recording:
...     written = export_wav(recording, os.path.join(folder, "wav"), print)
>>> import wave
>>> with wave.open(written[0]) as wav:
...     os.path.basename(written[0]), wav.getframerate(), wav.getnchannels(), wav.getnframes()
('pepper-mic.wav', 16000, 1, 640)
"""

from __future__ import annotations

import os
import wave
from collections.abc import Callable

from sonibus.bus.audio import AudioChunk
from sonibus.bus.keys import Key

from .reading import Recording

MAX_GAP_S = 60.0  # a seq gap longer than this (by t as well) is a clock or counter gone wrong: no hour of silence


def audio_keys(recording: Recording) -> list[str]:
    """The audio keys recorded (``<robot>/audio/<stream>``)."""
    return [k for k in recording.keys if Key.parse(k).section == "audio"]


def export_wav(recording: Recording, directory: str, say: Callable[[str], None]) -> list[str]:
    """Write a WAV file per audio key of ``recording`` into ``directory`` (created if
    needed); returns their paths. ``say`` gets a line per file that skipped chunks."""
    paths = []
    for key in audio_keys(recording):
        os.makedirs(directory, exist_ok=True)
        key_parts = Key.parse(key)
        paths.append(os.path.join(directory, f"{key_parts.robot}-{key_parts.name}.wav"))
        skipped = _write(recording, key, paths[-1])
        if skipped:
            count, found, kept = skipped
            say(f"{key}: {count} chunk{'s' if count != 1 else ''} skipped: {found}, not the {kept} of the "
                f"first chunk (the WAV's)")
    return paths


def _write(recording: Recording, key: str, path: str) -> tuple[int, str, str] | None:
    """Write ``key``'s chunks to ``path``; (how many, their format, the file's) of chunks skipped."""
    skipped, other = 0, ""
    first: AudioChunk | None = None
    last: AudioChunk | None = None
    with wave.open(path, "wb") as out:
        for message in recording.messages([key]):
            chunk = AudioChunk.of(message.data)
            if first is None:
                first = chunk
                out.setnchannels(chunk.channels)
                out.setsampwidth(2)
                out.setframerate(chunk.rate)
            elif (chunk.rate, chunk.channels) != (first.rate, first.channels):
                skipped, other = skipped + 1, other or _format(chunk)
                continue
            if last is not None and chunk.seq > last.seq + 1:
                out.writeframes(bytes(_silence(last, chunk) * 2 * chunk.channels))
            out.writeframes(chunk.pcm)
            last = chunk
    return (skipped, other, _format(first)) if skipped and first is not None else None


def _silence(last: AudioChunk, chunk: AudioChunk) -> int:
    """Frames of silence for the chunks missing between ``last`` and ``chunk``: as many
    as ``last`` held each; never more than their ``t`` apart allows, nor ``MAX_GAP_S``."""
    missing = (chunk.seq - last.seq - 1) * last.frames
    by_time = (chunk.t - last.t) * last.rate - last.frames
    if missing > by_time + last.rate:  # the counter jumped, not the time: trust the clock
        missing = max(0, round(by_time))
    return min(missing, int(MAX_GAP_S * last.rate))


def _format(chunk: AudioChunk) -> str:
    return f"{chunk.rate} Hz × {chunk.channels}"
