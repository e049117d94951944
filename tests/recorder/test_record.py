"""The recorder: every sample on the bus lands in the file, in order, schema-valid,
readable by the ``mcap`` library itself; a killed recorder loses at most its last
chunk; a full queue is counted, never silent."""

from __future__ import annotations

import json
import re
import signal
import threading
import time
from collections import defaultdict

import jsonschema
import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Channel, Footer
from mcap.records import Message as McapMessage
from mcap.stream_reader import StreamReader

from sonibus.adapters.recorder.channels import from_data
from sonibus.adapters.recorder.reading import Recording
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.bus import ConfigError
from sonibus.bus.codec import encode
from sonibus.bus.framing import frame, frame_samples

from ..conftest import SONIBUS, run_cli, wait_for
from .conftest import HEY, record_sim


def read_back(path):
    """Every message of ``path`` as (topic, log_time, publish_time, decoded), with the library's reader."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        out = [(channel.topic, message.log_time, message.publish_time,
                from_data(channel.message_encoding, message.data), schema)
               for schema, channel, message in reader.iter_messages(log_time_order=False)]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return summary, out, metadata


def test_every_sample_is_in_the_file_in_order_and_schema_valid(recorded):
    path, reference = recorded
    summary, messages, metadata = read_back(path)
    by_key = defaultdict(list)
    for topic, _, _, data, _ in messages:
        if topic == "pepper/frame":  # (issue 35: a frame is one message, its joints' samples in it)
            for name, sample in frame_samples(data):
                by_key[f"pepper/joints/{name}"].append(sample)
        by_key[topic].append(data)
    assert not any(topic.startswith("pepper/joints/") for topic, *_ in messages)
    assert len(by_key["pepper/frame"]) == len(by_key["pepper/joints/HeadYaw"])  # one message a frame
    seen = defaultdict(list)
    for key, data in reference:
        seen[key].append(data)
    assert len(seen["pepper/joints/HeadYaw"]) >= 100
    for key, data in seen.items():
        # Either may miss a frame at either end (a subscription still on the way, or already gone);
        # in between, the file holds exactly what the bus carried.
        if all("seq" in d for d in data):
            in_file, on_bus = ({d["seq"]: d for d in found} for found in (by_key[key], data))
            both = in_file.keys() & on_bus.keys()
            assert all(in_file[seq] == on_bus[seq] for seq in both), f"{key}: the file differs from the bus"
            assert len(both) >= max(len(in_file), len(on_bus)) - 2, f"{key}: {len(in_file)} in the file, " \
                f"{len(on_bus)} seen, {len(both)} in both"
        else:
            both = min(len(by_key[key]), len(data))
            assert by_key[key][-both:] == data[-both:], f"{key}: the file differs from what the bus carried"
            assert abs(len(by_key[key]) - len(data)) <= 2, f"{key}: {len(by_key[key])} in the file, {len(data)} seen"
    joints = [k for k in by_key if "/joints/" in k]
    assert len(joints) == 17
    frames = {key: [d["seq"] for d in by_key[key]] for key in joints}
    for key, seqs in frames.items():
        # A VM stall can make the robot skip frames (its pacer never bursts): such a gap in seq is
        # the robot's, on the bus as well (above). The file never reorders, and holds frames whole.
        assert seqs == sorted(set(seqs)), f"{key}: a reordering"
        assert seqs == frames["pepper/joints/HeadYaw"], f"{key}: not every frame holds every joint"
    behaviors = [(d["name"], d["state"]) for d in by_key["pepper/events/behavior"]]
    assert (HEY, "started") in behaviors
    assert any(d["state"] == "started" for d in by_key["pepper/events/speech"])
    assert by_key["pepper/info"][0]["robot"] == "pepper" and len(by_key["pepper/info"]) == 1
    # Times: log time never goes back; the publish time is the sample's own t.
    log_times = [log for _, log, _, _, _ in messages]
    assert log_times == sorted(log_times)
    for _, _, publish, data, _ in messages:
        if "t" in data:
            assert publish == int(data["t"] * 1e9)
    # Each channel carries its JSON Schema: the file validates by itself (as Foxglove reads it).
    for _, _, _, data, schema in messages:
        assert schema.encoding == "jsonschema" and schema.name.startswith(("sonibus.v1.", "foxglove."))
        jsonschema.validate(data, json.loads(schema.data))
    assert {c.message_encoding for c in summary.channels.values()} == {"json"}
    assert metadata["sonibus.stats"]["dropped"] == "0"
    assert metadata["sonibus.recording"]["node"] == "logger"


def test_a_key_expression_records_only_what_it_selects(net, tmp_path):
    path = tmp_path / "head.mcap"
    record_sim(net, path, frames=20, subscribe=("pepper/joints/Head*",), foxglove=False)  # (views: test_foxglove)
    _, messages, _ = read_back(path)
    assert {topic for topic, *_ in messages} == {"pepper/frame", "pepper/info"}
    assert {tuple(data["names"]) for topic, _, _, data, _ in messages if topic == "pepper/frame"} == \
        {("HeadYaw", "HeadPitch")}
    with Recording(str(path)) as recording:
        assert recording.keys == ["pepper/info", "pepper/joints/HeadPitch", "pepper/joints/HeadYaw"]


def test_a_full_queue_is_counted_and_reported(net, tmp_path):
    recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "slow.mcap"), queue=16), name="logger"))
    disk = threading.Event()
    write = recorder._series.writer.write_all

    def slow_disk(*args):  # a disk that stalls: the queue must fill and say so
        disk.wait(10)
        return write(*args)

    recorder._series.writer.write_all = slow_disk
    net.sim("pepper", rate_hz=100)
    wait_for(lambda: recorder.status()["dropped"] > 0, what="drops to be counted")
    disk.set()
    recorder.stop()
    _, _, metadata = read_back(tmp_path / "slow.mcap")
    assert int(metadata["sonibus.stats"]["dropped"]) == recorder._queue.dropped > 0
    assert "dropped" in str(recorder.status())


def test_sigkill_leaves_a_file_readable_up_to_its_last_chunk(net, tmp_path, spawn):
    path = tmp_path / "killed.mcap"
    recording = spawn(SONIBUS, "record", str(path), *net.cli_args())
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: path.exists() and path.stat().st_size > 20_000, timeout=20, what="two chunks on disk")
    recording.kill()
    messages, complete, encodings = [], False, {}
    with open(path, "rb") as f, pytest.raises(EndOfFile):  # it ends mid-record: that is the point
        for record in StreamReader(f).records:
            complete = complete or isinstance(record, Footer)
            if isinstance(record, McapMessage):
                messages.append(record)
            elif isinstance(record, Channel):
                encodings[record.id] = record.message_encoding
    assert not complete and len(messages) >= 17 * 10
    info = run_cli("info", str(path))
    assert info.returncode == 1
    assert "truncated" in info.stderr and "sonibus recover" in info.stderr and len(info.stderr.splitlines()) == 1
    saved = run_cli("recover", str(path))
    assert saved.returncode == 0, saved.stderr
    assert f"recovered {len(messages)} messages" in saved.stdout
    _, recovered, _ = read_back(tmp_path / "killed.recovered.mcap")
    assert [from_data(encodings[m.channel_id], m.data) for m in messages] == [data for _, _, _, data, _ in recovered]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_ends_recording_cleanly_with_a_summary(net, tmp_path, spawn, sig):
    path = tmp_path / "clean.mcap"
    recording = spawn(SONIBUS, "record", str(path), *net.cli_args(), "--status-every", "0.2")
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: path.exists() and path.stat().st_size > 5_000, timeout=20, what="data on disk")
    code, out, err = recording.stop(sig, timeout=3)
    assert code == 0, err
    assert out.startswith(f"recorded {path}") and "0 dropped" in out
    assert "recording " in err  # the status lines
    summary, messages, metadata = read_back(path)
    assert summary.statistics.message_count == len(messages) > 17
    assert metadata["sonibus.stats"]["dropped"] == "0"


def test_an_existing_file_is_kept_unless_forced(net, tmp_path):
    path = tmp_path / "keep.mcap"
    path.write_bytes(b"precious")
    with pytest.raises(ConfigError, match="exists"):
        net.start(Recorder(RecorderConfig(path=str(path)), name="logger"))
    assert path.read_bytes() == b"precious"
    net.start(Recorder(RecorderConfig(path=str(path), overwrite=True), name="logger")).stop()
    assert path.read_bytes().startswith(b"\x89MCAP")


def test_time_in_the_path_names_each_recording(net, tmp_path):
    recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "show-{time}.mcap")), name="logger"))
    recorder.stop()
    (made,) = tmp_path.glob("show-*.mcap")
    assert made.name[5:20].replace("-", "").isdigit()


def test_bad_options_name_the_key():
    with pytest.raises(ConfigError, match="key 'subscribe'"):
        RecorderConfig(path="x.mcap", subscribe=("a//b",))
    with pytest.raises(ConfigError, match="key 'path'"):
        RecorderConfig(path="")
    with pytest.raises(ConfigError, match="key 'queue'"):
        RecorderConfig(path="x.mcap", queue=0)


def test_record_cli_rejects_a_bad_key_expression(tmp_path):
    result = run_cli("record", str(tmp_path / "x.mcap"), "pepper//joints", "--no-multicast", "--duration", "1")
    assert result.returncode == 2
    assert "not a valid key expression" in result.stderr and len(result.stderr.splitlines()) == 1
    assert not (tmp_path / "x.mcap").exists()


def test_info_json_gives_numbers_as_numbers_and_the_total_record_said(net, tmp_path, spawn):
    """Issue 19, item 6: ``info --json`` gave the recorder's statistics as strings (MCAP metadata
    holds strings only). Issue 37, item 9: record said 54,010 messages where info said 60,378 of the
    same file (info counts the Foxglove views too): record's last line says both, its total is info's."""
    path = tmp_path / "numbers.mcap"
    recording = spawn(SONIBUS, "record", str(path), *net.cli_args())
    net.sim("pepper", rate_hz=50)
    wait_for(lambda: path.exists() and path.stat().st_size > 5_000, timeout=20, what="data on disk")
    code, out, err = recording.stop(signal.SIGINT, timeout=3)
    assert code == 0, err
    said = re.search(r"(\d+) messages \+ (\d+) for Foxglove's panels = (\d+) in the file", out)
    assert said, out
    data, views, total = map(int, said.groups())
    assert data + views == total and views > 0
    result = run_cli("info", str(path), "--json")
    assert result.returncode == 0, result.stderr
    facts = json.loads(result.stdout)
    stats = facts["stats"]
    assert stats["dropped"] == 0 and isinstance(stats["received"], int) and stats["received"] > 0, stats
    assert facts["messages"] == total, (out, result.stdout[:300])


def test_a_recorders_relative_path_is_the_installation_files_folder(tmp_path, spawn):
    """Issue 37, item 9: one rule for relative paths (the [log] file's already): a recorder's path
    was taken from where `sonibus run` started, so a service and a hand run recorded to two places."""
    folder = tmp_path / "show"
    folder.mkdir()
    (folder / "show.toml").write_text('[bus]\nmulticast = false\n\n[nodes.pepper]\nadapter = "sim"\nrate_hz = 50\n\n'
                                      '[nodes.rec]\nadapter = "recorder"\npath = "recs/take.mcap"\n', encoding="utf-8")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    run = spawn(SONIBUS, "run", str(folder / "show.toml"), cwd=str(elsewhere))
    wait_for(lambda: (folder / "recs" / "take.mcap").exists(), 20, "the recording beside the installation file")
    code, _, err = run.stop(signal.SIGINT, timeout=5)
    assert code in (0, 130), err
    assert not (elsewhere / "recs").exists()


def test_what_comes_while_the_recorder_stops_is_written_not_left_in_its_queue(net, tmp_path):
    """Stop woke the writer (gathering 50 ms at a time) before the subscriptions ended: what they
    queued meanwhile stayed in a queue nobody read, counted nowhere. A robot publishing as fast
    as it can while the recorder stops: nothing is left behind."""
    recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "stop.mcap"), foxglove=False), name="rec"))
    robot = net.bus("robot")
    publisher = robot.stream_publisher("pepper/frame")
    publishing = threading.Event()
    publishing.set()

    def publish() -> None:
        seq = 0
        while publishing.is_set():
            seq += 1
            publisher.put(encode(frame(time.time(), seq, ["HeadYaw"], [0.1])))
            time.sleep(0.0002)

    undeclare = recorder._streams.undeclare

    def slowly() -> None:  # (as on a busy machine: the subscriptions end a moment after stop is said)
        time.sleep(0.2)
        undeclare()

    recorder._streams.undeclare = slowly
    thread = threading.Thread(target=publish)
    thread.start()
    try:
        wait_for(lambda: recorder.stats["written"] > 50, what="frames written")
        recorder.stop()
    finally:
        publishing.clear()
        thread.join(5)
    assert len(recorder._queue) == 0, f"{len(recorder._queue)} samples left in the queue at stop"
