"""The recorder never dies quietly: garbage on the bus is counted and skipped
while recording goes on; a disk that fills under it ends ``sonibus record`` at
once with one error line naming the file, leaving what it wrote recoverable
(the disk guard, which stops before that, is tests/recorder/test_disk.py); a
path that cannot be written is a configuration error (exit 2) before anything
runs."""

from __future__ import annotations

import math
import os
import random
import re
import shutil
import signal
import subprocess
import tempfile
import threading
import time

import msgpack
import pytest

from sonibus.adapters.recorder import Recording, recover
from sonibus.bus import framing

from ..conftest import SONIBUS, run_cli, wait_for
from .conftest import tmpfs
from .test_cut_files import passes_every_reader

STATUS = re.compile(r"recording .*: [\d.]+ s, (\d+) messages .*, (\d+) dropped, (\d+) bad")


def status(process):
    """(messages, bad) of the last status line ``sonibus record`` wrote, or None."""
    for line in reversed(process.lines):
        found = STATUS.search(line)
        if found:
            return int(found[1]), int(found[3])
    return None


def put(bus, key, message):
    """``put K X`` of issue 13: X packed as any msgpack client would, bytes and all."""
    bus.session.put(key, msgpack.packb(message, use_bin_type=True))


def test_garbage_on_the_bus_is_counted_and_recording_goes_on(net, tmp_path, spawn):
    path = tmp_path / "garbage.mcap"
    recording = spawn(SONIBUS, "record", str(path), *net.cli_args(), "--status-every", "0.1",
                      collect=True, merge=True)
    bus = net.bus("stranger")
    wait_for(lambda: put(bus, "pepper/events/probe", {"t": time.time(), "kind": "probe"}) or
             (status(recording) or (0, 0))[0] >= 1, timeout=20, what="the recorder to take events",
             explain=lambda: "\n".join(recording.lines))
    now = time.time()
    garbage = [
        ("pepper/events/behavior", {"t": now, "kind": "behavior", "name": b"x"}),
        ("pepper/frame", {"t": 1e12, "seq": 1, "names": ["HeadYaw"], "v": [0.1]}),
        ("pepper/frame", {"t": now, "seq": 2, "names": ["HeadYaw"], "v": [math.nan]}),
        ("pepper/frame", {"t": now + 3600, "seq": 3, "names": ["HeadYaw"], "v": [0.1]}),
        ("pepper/events/speech", {"t": now, "kind": "speech", "text": msgpack.ExtType(5, b"boo")}),
    ]
    for key, message in garbage:
        put(bus, key, message)
    before = status(recording)[0]
    put(bus, "pepper/events/behavior", {"t": time.time(), "kind": "behavior", "name": "after the garbage",
                                         "state": "started"})
    wait_for(lambda: status(recording) >= (before + 1, len(garbage)), timeout=10,
             what="the event after the garbage recorded and the garbage counted",
             explain=lambda: "\n".join(recording.lines[-5:]))
    code, rest, _ = recording.stop(signal.SIGINT)
    said = [*recording.lines, *rest.splitlines()]  # (the last lines may come with the process's end)
    assert code == 0, "\n".join(said)
    assert any(line.startswith(f"recorded {path}") and line.endswith(f"{len(garbage)} bad") for line in said), said
    found = passes_every_reader(path, tmp_path)
    assert [d["name"] for k, _, d in found if k == "pepper/events/behavior"] == ["after the garbage"]
    assert not any(k == "pepper/joints/HeadYaw" for k, _, _ in found)
    with Recording(str(path)) as done:
        assert int(done.metadata["sonibus.stats"]["bad"]) == len(garbage)


@pytest.fixture
def small_disk():
    """A 1 MiB file system of its own (a chunk of the frames below, which no compression shrinks
    much, takes ~0.4 MB on disk: 256 KiB held none since frames are one message each, issue 35)."""
    with tmpfs("1m") as folder:
        yield folder


def test_a_full_disk_ends_the_recorder_loudly_and_leaves_a_recoverable_file(net, tmp_path, spawn, small_disk):
    """With the disk guard off (--min-free-mb 0), the disk fills under the writer."""
    path = os.path.join(small_disk, "show.mcap")
    recording = spawn(SONIBUS, "record", path, *net.cli_args(), "--status-every", "0.5", "--min-free-mb", "0")
    publisher = net.bus("robot").stream_publisher("pepper/frame")
    names = [f"Joint{i}" for i in range(100)]
    stop = threading.Event()

    def flood():  # frames no compression can shrink much, until the recorder is gone
        seq = 0
        while not stop.wait(0.001):
            values = [random.uniform(-1, 1) for _ in names]
            publisher.put(msgpack.packb(framing.frame(time.time(), seq, names, values)))
            seq += 1

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    try:
        wait_for(lambda: recording.popen.poll() is not None or shutil.disk_usage(small_disk).free < 64 * 1024,
                 timeout=60, what="the disk to fill")
        wait_for(lambda: recording.popen.poll() is not None, timeout=5, what="the recorder to end on a full disk")
    finally:
        stop.set()
        flooder.join(5)
    code, _, err = recording.stop()
    assert code == 1, err
    last = err.strip().splitlines()[-1]
    assert last == f"sonibus: error: node 'record': cannot write {path}: No space left on device", err
    assert "Traceback" not in err, "a failure the code foresaw is its line, not a traceback"
    copy = tmp_path / "show.mcap"
    shutil.copy(path, copy)
    out = tmp_path / "show.recovered.mcap"
    kept, _ = recover(str(copy), str(out))
    assert kept >= 10  # frames of 100 joints, one message each
    passes_every_reader(out, tmp_path)


CANNOT_WRITE = {  # what a path is → (path under a scratch folder, what the error says)
    "a folder": ("folder", "is a folder — name a file in it"),
    "in a file": ("notes.txt/show.mcap", "notes.txt is a file, not a folder"),
    "in /proc": ("/proc/show.mcap", "cannot write /proc/show.mcap: No such file or directory"),
    "in a folder /proc cannot have": ("/proc/recordings/show.mcap", "cannot write /proc/recordings/show.mcap"),
    "on a read-only file system": ("readonly/show.mcap", "is on a read-only file system"),
}


@pytest.fixture
def scratch(tmp_path):
    """A folder with a sub-folder, a file and a read-only file system in it."""
    (tmp_path / "folder").mkdir()
    (tmp_path / "notes.txt").write_text("notes")
    (tmp_path / "readonly").mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k,ro", "tmpfs", str(tmp_path / "readonly")], check=True)
    try:
        yield tmp_path
    finally:
        subprocess.run(["umount", "-l", str(tmp_path / "readonly")], check=False)


def one_error_line(result):
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert result.stderr.startswith("sonibus: error: ") and len(result.stderr.splitlines()) == 1, result.stderr
    return result.stderr


@pytest.mark.parametrize("case", sorted(CANNOT_WRITE))
def test_record_into_a_path_that_cannot_be_written_is_a_usage_error(scratch, case):
    where, why = CANNOT_WRITE[case]
    path = str(scratch / where)
    error = one_error_line(run_cli("record", path, "--no-multicast", "--duration", "5"))
    assert "node 'record': key 'path': " in error and path in error and why in error, error


@pytest.mark.parametrize("case", sorted(CANNOT_WRITE))
def test_an_installation_with_such_a_recorder_is_refused(scratch, case):
    where, why = CANNOT_WRITE[case]
    path = str(scratch / where)
    config = scratch / "show.toml"
    config.write_text(f'[nodes.robot]\nadapter = "sim"\n\n[nodes.logger]\nadapter = "recorder"\npath = "{path}"\n')
    error = one_error_line(run_cli("run", str(config), "--no-multicast"))
    assert "key 'path'" in error and path in error and why in error, error
    # found when the file is loaded, or (/proc) opened at start: either way its name, table and line
    assert f"{config} [nodes.logger] line 6: key 'path': " in error, error


def test_no_permission_to_write_is_a_usage_error(tmp_path):
    """As a user who may not write in the folder (root may write anywhere)."""
    ours = tempfile.mkdtemp(prefix="sonibus-perm-")  # (pytest's tmp_path is in a folder only root may enter)
    try:
        os.chmod(ours, 0o755)
        folder = os.path.join(ours, "theirs")
        os.mkdir(folder, mode=0o755)
        as_nobody = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", SONIBUS, "record"]
        cases = ((os.path.join(folder, "show.mcap"), f"cannot be created: no permission to write in {folder}"),
                 (str(tmp_path / "show.mcap"), f"cannot be created: no permission to enter {tmp_path.parent}"))
        for path, why in cases:
            result = subprocess.run([*as_nobody, path, "--no-multicast", "--duration", "5"],
                                    capture_output=True, text=True, timeout=20)
            error = one_error_line(result)
            assert f"node 'record': key 'path': {path} {why}" in error, error
    finally:
        shutil.rmtree(ours)
