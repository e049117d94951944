"""Recordings for days: a new file by size or by time, each named by when it
starts, each finished with its summary and standing alone (the robots' info at
its start: ``info``, ``export`` and replay read any one of them), and no
message lost or written twice across a change of file."""

from __future__ import annotations

import os
import random
import re
import time

import msgpack
import zenoh

from sonibus.adapters.recorder import Recording
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.bus import framing, robot_info

from ..conftest import run_cli, wait_for
from .conftest import settle

NAME = re.compile(r"show-\d{8}-\d{6}(-\d+)?\.mcap")
JOINTS = [f"Joint{i}" for i in range(10)]


def read_all(paths):
    """Each file whole, with the library's checks: {path: (recording facts, [(key, data)])}."""
    found = {}
    for path in paths:
        with Recording(path) as recording:
            found[path] = (recording.metadata, recording.infos(), [(m.key, m.data) for m in recording.messages()])
    return found


def test_rotation_by_size_loses_and_repeats_no_message(net, tmp_path):
    recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "show-{time}.mcap"), rotate_mb=0.02,
                                                 flush_s=0.1), name="logger"))
    first = recorder.address
    publisher = net.bus("robot").session.declare_publisher("pepper/frame",
                                                           congestion_control=zenoh.CongestionControl.BLOCK)
    wait_for(lambda: publisher.matching_status.matching, what="the recorder's subscription")
    frames = 0
    deadline = time.monotonic() + 30
    while len(recorder.files) < 4 and time.monotonic() < deadline:  # frames no compression shrinks much
        publisher.put(msgpack.packb(framing.frame(time.time(), frames, JOINTS,
                                                   [random.uniform(-1, 1) for _ in JOINTS])))
        frames += 1
        time.sleep(0.002)
    for _ in range(5):  # (the 4th file may have just opened, between two frames: it gets some, not 20 KB)
        publisher.put(msgpack.packb(framing.frame(time.time(), frames, JOINTS, [0.0] * len(JOINTS))))
        frames += 1
    wait_for(lambda: recorder.stats["written"] == frames * len(JOINTS), what="every frame written",
             explain=lambda: f"{recorder.stats['written']} of {frames * len(JOINTS)}")
    recorder.stop()

    files = recorder.files
    assert len(files) >= 4 and files[0] == first and recorder.address == files[-1]
    assert [os.path.basename(p) for p in sorted(files)] == [os.path.basename(p) for p in files]  # ls: in order
    assert all(NAME.fullmatch(os.path.basename(p)) for p in files), files
    found = read_all(files)  # (Recording refuses a file without its summary)
    seqs = {joint: [] for joint in JOINTS}
    for n, path in enumerate(files):
        metadata, _, held = found[path]
        assert metadata["sonibus.recording"]["part"] == str(n + 1)
        assert metadata["sonibus.recording"]["previous"] == (os.path.basename(files[n - 1]) if n else "")
        in_file = {}
        for key, data in held:
            if key.startswith("pepper/joints/"):
                in_file.setdefault(data["seq"], set()).add(key)
                seqs[key.rsplit("/", 1)[1]].append(data["seq"])
        assert all(len(joints) == len(JOINTS) for joints in in_file.values()), f"{path}: a frame cut in two"
        assert int(metadata["sonibus.stats"]["written"]) == len(in_file) * len(JOINTS)  # the file's own count
    for joint, got in seqs.items():
        assert got == list(range(frames)), f"{joint}: {len(got)} samples for {frames} frames sent"


def test_rotation_by_time_makes_files_that_stand_alone(net, tmp_path):
    recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "show-{time}.mcap"), rotate_s=1),
                                  name="logger"))
    sim = net.sim("pepper", rate_hz=50, body_sound=False)
    watch = net.bus("watch")
    wait_for(lambda: len(recorder.files) >= 4, timeout=20, what="four files")
    sim.stop()
    settle(lambda: recorder.stats["received"])
    recorder.stop()

    files = recorder.files
    found = read_all(files)
    head_yaw = []
    for path in files[:-1]:  # (the last may have begun after the robot stopped)
        _, infos, held = found[path]
        assert infos["pepper"]["robot"] == "pepper", f"{path} does not start with pepper's info"
        head_yaw += [data["seq"] for key, data in held if key == "pepper/joints/HeadYaw"]
    assert head_yaw == sorted(set(head_yaw)), "a frame written twice, or out of order, across files"
    assert sum(int(metadata["sonibus.stats"]["written"]) for metadata, _, _ in found.values()) \
        == recorder.stats["written"]  # (each file counts its own; the info copies at their starts are not counted)

    middle = files[1]
    info = run_cli("info", middle)
    assert info.returncode == 0 and "robot pepper: pepper, 17 joints" in info.stdout, info.stdout + info.stderr
    assert f"(after {os.path.basename(files[0])})" in info.stdout, info.stdout
    exported = run_cli("export", middle, "--csv", str(tmp_path / "csv"))
    assert exported.returncode == 0 and (tmp_path / "csv" / "pepper.csv").exists(), exported.stderr
    replay = net.start(Replay(ReplayConfig(path=middle, rename={"pepper": "take1"}), name="replay"))
    replayed = wait_for(lambda: robot_info(watch, "take1", timeout=0.5), what="take1's info, from the middle file")
    assert replayed["model"] == "pepper" and replayed["replay"]["file"] == os.path.basename(middle)
    wait_for(replay.finished.is_set, timeout=10, what="the replay's end")
    assert replay.stats["sent"] > 0
