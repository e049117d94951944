"""WAV export of a recording's audio: one file per audio key, ``<robot>-<stream>.wav``.

Samples are written as recorded (int16, at the rate and channel count of the
key's first chunk). A gap in ``seq`` (chunks lost on the way, or dropped by
the recorder) becomes silence of the missing chunks' length, so the file keeps
time; a ``seq`` that goes back (the publisher restarted) is played on as it
comes. A chunk of another rate or channel count than the first is skipped, and
said once per file; a message that is no audio chunk never comes here (the
recording's reader checks each like the gate, and counts what it skips), and a
key with none gets no file.

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
from typing import Any

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
        path = os.path.join(directory, f"{key_parts.robot}-{key_parts.name}.wav")
        written = _Writer(path)
        try:
            for message in recording.messages([key]):
                written.add(message.data)
        finally:
            written.close()
        if written.skipped and written.first is not None:
            count, found = written.skipped, written.other
            say(f"{key}: {count} chunk{'s' if count != 1 else ''} skipped: {found}, not the "
                f"{_format(written.first)} of the first chunk (the WAV's)")
        if written.first is not None:
            paths.append(path)
    return paths


class _Writer:
    """One key's chunks into a WAV file, opened at the first good chunk (its format)."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.first: AudioChunk | None = None
        self.last: AudioChunk | None = None
        self.skipped, self.other = 0, ""    # chunks of another format than the first
        self._out: wave.Wave_write | None = None

    def add(self, message: Any) -> None:
        """One audio chunk, checked by the gate (``reading.Checks``)."""
        chunk = AudioChunk.of(message)
        if self._out is None:
            self.first = chunk
            self._out = wave.open(self.path, "wb")  # noqa: SIM115 (closed by close(), after the last chunk)
            self._out.setnchannels(chunk.channels)
            self._out.setsampwidth(2)
            self._out.setframerate(chunk.rate)
        elif self.first is not None and (chunk.rate, chunk.channels) != (self.first.rate, self.first.channels):
            self.skipped, self.other = self.skipped + 1, self.other or _format(chunk)
            return
        if self.last is not None and chunk.seq > self.last.seq + 1:
            self._out.writeframes(bytes(_silence(self.last, chunk) * 2 * chunk.channels))
        self._out.writeframes(chunk.pcm)
        self.last = chunk

    def close(self) -> None:
        if self._out is not None:
            self._out.close()


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
