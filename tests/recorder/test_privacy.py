"""Microphones are recorded only when named: a robot's microphones carry what
visitors say. The default records no audio; naming ``*/audio/mic`` records it,
and the recorder says so at start, in one line. The help, README and
docs/recorder.md say the same default."""

from __future__ import annotations

import logging
from pathlib import Path

from sonibus.adapters.recorder import Recording
from sonibus.adapters.recorder.recorder import EVERYTHING, Recorder, RecorderConfig

from ..conftest import run_cli, wait_for

ROOT = Path(__file__).resolve().parents[2]


def test_the_default_records_no_microphone_and_naming_it_does(net, tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="sonibus")
    default = net.start(Recorder(RecorderConfig(path=str(tmp_path / "default.mcap")), name="logger"))
    named = net.start(Recorder(RecorderConfig(path=str(tmp_path / "mic.mcap"), subscribe=(*EVERYTHING, "*/audio/mic")),
                               name="mics"))
    net.sim("pepper", rate_hz=50, body_sound=True)  # microphones hearing its motors, while anyone subscribes
    wait_for(lambda: default.stats["written"] > 17 * 50 and named.stats["written"] > 17 * 50 + 50,
             timeout=20, what="a second of frames, and audio for the one that names it")
    default.stop()
    named.stop()
    with Recording(str(tmp_path / "default.mcap")) as recording:
        assert "pepper/joints/HeadYaw" in recording.keys
        assert not [k for k in recording.keys if "/audio/" in k], recording.keys
    with Recording(str(tmp_path / "mic.mcap")) as recording:
        assert recording.counts["pepper/audio/mic"] > 10
    said = [r.getMessage() for r in caplog.records if "records the microphones" in r.getMessage()]
    assert len(said) == 1 and said[0].startswith("mics: records the microphones (*/audio/mic)"), said
    assert "a venue needs their consent" in said[0]


def test_help_readme_and_docs_say_the_same_default():
    shown = run_cli("record", "--help").stdout
    flat = " ".join(shown.split())
    assert f"default: {' '.join(EVERYTHING)}" in flat and "no audio: microphones only when named" in flat, shown
    listed = ", ".join(f"`{p}`" for p in EVERYTHING)
    for doc in ("README.md", "docs/recorder.md"):
        text = " ".join((ROOT / doc).read_text().split())
        assert listed in text and "microphones only when named" in text, doc
        assert "`*/audio/*`)" not in text, f"{doc} still lists audio in the default"
