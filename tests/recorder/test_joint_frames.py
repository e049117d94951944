"""Issue 35: the recorder writes a robot's frame as ONE MCAP message on ``<robot>/frame`` (its
selected joints) where it wrote a message per joint key beside Foxglove's view of the frame.
Readers take it apart into the samples of the joint keys, so export, ``sonibus info``, plot and
replay give what a recording of the old layout gives. ``data/joints-per-key-5e09bd8.mcap`` is
such an old recording (sonibus at 5e09bd8: sim pepper at 50 Hz running Hey_1 and speech,
features, Foxglove's views; ~1 s); ``new_layout`` writes the same input as the recorder now
does: the frames (what was the view) as the joints' channel, no joint keys, the rest as it was."""

from __future__ import annotations

import filecmp
import io
import json
import threading
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import Writer

from sonibus.adapters.recorder.channels import from_data
from sonibus.adapters.recorder.export import export_csv
from sonibus.adapters.recorder.reading import Recording
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.adapters.recorder.writer import RecordingWriter
from sonibus.bus import decode, framing, load_model
from sonibus.bus.cli import Environment, main

from ..conftest import wait_for
from .conftest import settle
from .test_export import ns, t_of, value, write_info

OLD = Path(__file__).parent / "data" / "joints-per-key-5e09bd8.mcap"


def new_layout(old: Path, path: Path) -> Path:
    """``old``'s messages as the recorder writes them since issue 35: its frames (Foxglove's view of
    the joint samples beside them) on ``<robot>/frame`` as the joints' own channel, no joint key."""
    with open(old, "rb") as f, RecordingWriter(str(path)) as out:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if "/joints/" not in channel.topic:
                out.write(channel.topic, message.log_time, from_data(channel.message_encoding, message.data))
    return path


def cli(*argv: str) -> tuple[int, str, str]:
    """``sonibus ARGV`` in this process: its exit status, stdout and stderr."""
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    return main(list(argv), env), env.stdout.getvalue(), env.stderr.getvalue()


def test_a_new_file_reads_exports_and_says_what_an_old_one_of_the_same_input_does(tmp_path):
    new = new_layout(OLD, tmp_path / "new.mcap")
    with Recording(str(OLD)) as old_file, Recording(str(new)) as new_file:
        assert new_file._counts["pepper/frame"] == 51 and not any("/joints/" in k for k in new_file._counts)
        assert old_file.frames == {"pepper/derived"} and "pepper/frame" in old_file.views  # (the frame: a view)
        assert new_file.frames == {"pepper/frame", "pepper/derived"} and "pepper/frame" not in new_file.views
        assert new_file.keys == old_file.keys and len([k for k in new_file.keys if "/joints/" in k]) == 17
        assert new_file.counts == {k: n for k, n in old_file.counts.items() if k != "pepper/frame"}  # (the view)
        assert new_file.counts["pepper/joints/HeadYaw"] == 51
        assert new_file.message_count == old_file.message_count - 51 == sum(1 for _ in new_file.messages())
        for keys in (None, ["pepper/joints/HeadYaw", "pepper/events/speech"], new_file.matching(["*/joints/R*"])):
            assert [(m.key, m.log_ns, m.publish_ns, m.data) for m in new_file.messages(keys)] == \
                [(m.key, m.log_ns, m.publish_ns, m.data) for m in old_file.messages(keys) if m.key != "pepper/frame"]
        # what replay reads: a frame whole, with only the joints asked for
        frames = [m.data for m in new_file.messages(["pepper/joints/HeadYaw", "pepper/joints/HipRoll"], frames=True)
                  if m.key == "pepper/frame"]
        assert len(frames) == 51 and all(f["names"] == ["HeadYaw", "HipRoll"] and len(f["v"]) == 2 for f in frames)
        assert new_file.infos() == old_file.infos()
        # the frames asked for by their channel: whole, as the view of an old file gives them
        assert [m.data for m in new_file.messages(["pepper/frame"])] == \
            [m.data for m in old_file.messages(["pepper/frame"])]
    paths = {}
    for name, path in (("old", OLD), ("new", new)):
        with Recording(str(path)) as recording:
            paths[name] = export_csv(recording, str(tmp_path / name))
    assert [Path(p).name for p in paths["new"]] == ["pepper.csv", "pepper-derived.csv", "events.csv"]
    assert all(filecmp.cmp(a, b, shallow=False) for a, b in zip(paths["old"], paths["new"], strict=True))
    said = {}
    for name, path in (("old", OLD), ("new", new)):
        status, out, err = cli("info", str(path), "--json")
        assert status == 0 and err == "", err
        said[name] = json.loads(out)
    assert said["new"]["keys"] == said["old"]["keys"] and said["new"]["robots"] == said["old"]["robots"]
    assert said["new"]["messages"] == said["old"]["messages"] - 51  # (the frames' view, now the joints themselves)


def replayed(net, paths: dict[str, Path]) -> dict[str, tuple[Replay, list]]:
    """Each of ``paths`` (bus name → file) replayed to its end at once, with what each sent on its frame and
    joint keys."""
    lock = threading.Lock()
    watch = net.bus("watch")
    out: dict[str, tuple[Replay, list]] = {}
    subscribers = []
    for name, path in paths.items():
        seen: list = []

        def take(sample, seen=seen) -> None:
            with lock:
                seen.append((str(sample.key_expr), decode(sample.payload.to_bytes())))

        subscribers += [watch.session.declare_subscriber(f"{name}/{what}", take) for what in ("frame", "joints/*")]
        out[name] = (net.start(Replay(ReplayConfig(path=str(path), speed=10.0, rename={"pepper": name}), name=name)),
                     seen)
    for name, (replay, _) in out.items():
        wait_for(replay.finished.is_set, timeout=20, what=f"the end of the replay of {paths[name].name}")
    settle(lambda: [len(seen) for _, seen in out.values()])
    for subscriber in subscribers:
        subscriber.undeclare()
    return out


def test_an_old_and_a_new_file_of_the_same_input_replay_the_same_frames_and_joint_samples(net, tmp_path):
    new = new_layout(OLD, tmp_path / "new.mcap")
    with Recording(str(OLD)) as recording:
        recorded = [{q: v for q, v in m.data.items() if q != "t"} for m in recording._raw(["pepper/frame"])]
    assert len(recorded) == 51
    for name, (replay, seen) in replayed(net, {"take_old": OLD, "take_new": new}).items():
        frames = [m for key, m in seen if key == f"{name}/frame"]
        # every frame as recorded, in order (one more than 100 ms late on a stalled machine: skipped whole, counted)
        got = [{q: v for q, v in f.items() if q != "t"} for f in frames]  # (t: moved to now)
        left = iter(recorded)
        assert all(frame in left for frame in got) and len(got) + replay.stats["late"] // 17 == len(recorded), name
        assert replay.stats["frames"] == len(got) and replay.problems == ""
        joints = {(key.rpartition("/")[2], m["seq"]): m for key, m in seen if "/joints/" in key}
        assert joints == {(joint, f["seq"]): sample for f in frames for joint, sample in framing.frame_samples(f)}


def test_a_bad_frame_in_a_file_is_skipped_with_one_line_and_the_rest_exports_and_replays(net, tmp_path):
    path = tmp_path / "crafted.mcap"
    names = [j.name for j in load_model("pepper").joints]
    good = {seq: framing.frame(t_of(seq), seq, names, [value(seq, j) for j in range(len(names))])
            for seq in range(6)}
    crafted = {2: {**good[2], "v": good[2]["v"][:-1]},                 # a value short
               4: {**good[4], "names": [*names[:-1], names[0]]}}       # a joint twice
    with RecordingWriter(str(path)) as out:  # (the writer checks JSON only: a stranger's file may hold anything)
        write_info(out)
        for seq in range(6):
            out.write("pepper/frame", ns(t_of(seq)), crafted.get(seq, good[seq]))
    status, _, err = cli("export", str(path), "--csv", str(tmp_path / "csv"))
    assert status == 0, err
    (line,) = err.splitlines()
    assert line.startswith(f"sonibus: WARNING: {path}: skipped 2 messages (the first: pepper/frame: "), line
    rows = (tmp_path / "csv" / "pepper.csv").read_text(encoding="utf-8").splitlines()
    assert [row.split(",")[2] for row in rows[1:]] == ["0", "1", "3", "5"]  # (seq: the good frames, whole)
    ((replay, seen),) = replayed(net, {"take1": path}).values()
    assert replay.stats["frames"] + replay.stats["late"] // len(names) == 4
    assert "skipped 2 messages (the first: pepper/frame: " in replay.problems
    assert {m["seq"] for key, m in seen if key == "take1/frame"} <= {0, 1, 3, 5}


def test_an_old_file_whose_statistics_count_no_channel_is_not_read_twice(tmp_path):
    """MCAP lets a writer leave the per-channel counts out of its statistics (a tool's copy, a
    hand-made file): the old layout was then told by joint channels *with messages*, found none,
    and read Foxglove's view of the frames as the joints a second time."""
    copy = tmp_path / "no-channel-counts.mcap"
    with open(OLD, "rb") as f, open(copy, "wb") as out:
        reader = make_reader(f)
        writer = Writer(out)
        writer.start(profile="", library="a tool that counts no channel")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.id not in channels:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas.get(schema.id, 0) if schema else 0,
                    dict(channel.metadata))
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer._Writer__statistics.channel_message_counts.clear()  # (what such a writer leaves out)
        writer.finish()
    with Recording(str(OLD)) as old, Recording(str(copy)) as crafted:
        assert [(m.key, m.log_ns) for m in crafted.messages()] == [(m.key, m.log_ns) for m in old.messages()]
