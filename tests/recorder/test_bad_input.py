"""Files and arguments that are not what they should be: one clear line, a
non-zero exit, nothing written over."""

from __future__ import annotations

import shutil

import pytest

from sonibus.adapters.recorder import Recording, RecordingError
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig

from ..conftest import run_cli

READERS = {  # every subcommand that reads a recording, with what else it needs
    "info": lambda tmp: [],
    "replay": lambda tmp: ["--no-multicast"],
    "export": lambda tmp: ["--csv", str(tmp / "csv")],
    "plot": lambda tmp: ["-o", str(tmp / "out.png")],
}


def fails(tmp_path, command, path, *extra, why):
    result = run_cli(command, str(path), *READERS[command](tmp_path), *extra)
    assert result.returncode == 1, (command, result.stdout, result.stderr)
    assert result.stderr.startswith("sonibus: error: ") and len(result.stderr.splitlines()) == 1, result.stderr
    assert why in result.stderr, result.stderr
    assert not (tmp_path / "csv").exists() and not (tmp_path / "out.png").exists()
    return result.stderr


@pytest.mark.parametrize("command", sorted(READERS))
def test_a_file_that_is_not_mcap(tmp_path, command):
    path = tmp_path / "notes.mcap"
    path.write_text("these are my notes, not a recording\n")
    fails(tmp_path, command, path, why="is not an MCAP file")


@pytest.mark.parametrize("command", sorted(READERS))
def test_a_truncated_file_points_to_recover(tmp_path, recorded, command):
    path = tmp_path / "cut.mcap"
    data = recorded[0].read_bytes()
    path.write_bytes(data[: len(data) // 2])
    fails(tmp_path, command, path, why=f"is truncated: it was not closed cleanly (a killed recorder, a full disk, "
                                       f"an unfinished copy); 'sonibus recover {path}'")


@pytest.mark.parametrize("command", sorted(READERS))
def test_an_empty_recording(net, tmp_path, command):
    path = tmp_path / "empty.mcap"
    net.start(Recorder(RecorderConfig(path=str(path)), name="logger")).stop()
    fails(tmp_path, command, path, why="is an empty recording: it holds no messages")


@pytest.mark.parametrize("command", sorted(READERS))
def test_a_zero_byte_file_and_a_missing_one(tmp_path, command):
    (tmp_path / "zero.mcap").write_bytes(b"")
    fails(tmp_path, command, tmp_path / "zero.mcap", why="is empty (0 bytes)")
    fails(tmp_path, command, tmp_path / "missing.mcap", why="No such file")


@pytest.mark.parametrize("command", ["replay", "plot"])
def test_a_key_expression_that_selects_nothing_lists_what_there_is(tmp_path, recorded, command):
    error = fails(tmp_path, command, recorded[0], "--keys", "nao/**", why="no key in")
    assert "nao/**" in error and "pepper/events/behavior" in error


@pytest.mark.parametrize("command", ["replay", "plot"])
def test_an_invalid_key_expression(tmp_path, recorded, command):
    result = run_cli(command, str(recorded[0]), *READERS[command](tmp_path), "--keys", "pepper//joints")
    assert result.returncode in (1, 2) and "not a valid key expression" in result.stderr
    assert len(result.stderr.splitlines()) == 1


def test_replay_arguments_that_cannot_work(tmp_path, recorded):
    path = str(recorded[0])
    for args, why in ((["--as", "nao=x"], "no robot 'nao'"), (["--speed", "0"], "speed"),
                      (["--start", "999"], "lasts only"), (["--start", "2", "--end", "1"], "end"),
                      (["--as", "bad/name"], "robot name")):
        result = run_cli("replay", path, "--no-multicast", *args)
        assert result.returncode in (1, 2), (args, result.stderr)
        assert why in result.stderr and len(result.stderr.splitlines()) == 1, (args, result.stderr)


def test_recover_refuses_what_it_cannot_help(tmp_path, recorded):
    (tmp_path / "notes.mcap").write_text("not mcap")
    result = run_cli("recover", str(tmp_path / "notes.mcap"))
    assert result.returncode == 1 and "is not an MCAP file" in result.stderr
    shutil.copy(recorded[0], tmp_path / "whole.mcap")
    (tmp_path / "whole.recovered.mcap").write_bytes(b"keep me")
    result = run_cli("recover", str(tmp_path / "whole.mcap"))
    assert result.returncode == 1 and "exists" in result.stderr
    assert (tmp_path / "whole.recovered.mcap").read_bytes() == b"keep me"


def test_the_reader_says_the_same_in_python(tmp_path):
    (tmp_path / "notes.mcap").write_text("not mcap")
    with pytest.raises(RecordingError, match="is not an MCAP file"):
        Recording(str(tmp_path / "notes.mcap"))
