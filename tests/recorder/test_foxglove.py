"""Recordings that open well in Foxglove (the default; ``foxglove = false`` leaves it out): each robot's frames
whole, its events as ``foxglove.Log``, its arms as ``foxglove.FrameTransforms``
and its processors' ``info/derived``, each channel with its schema (Foxglove's
published one, or sonibus's), read back with the ``mcap`` library; bus readers
(replay, export) see the same keys as without them."""

from __future__ import annotations

import json
from collections import defaultdict
from typing import Any

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from sonibus import schemas
from sonibus.adapters.features import Features
from sonibus.adapters.features.config import FeaturesConfig
from sonibus.adapters.features.kinematics import load_arms
from sonibus.adapters.recorder import Recording
from sonibus.adapters.recorder.channels import from_data
from sonibus.adapters.recorder.export import export_csv
from sonibus.adapters.recorder.recorder import Recorder, RecorderConfig
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.schemas import foxglove

from ..conftest import Network, run_cli, wait_for
from ..foxglove.test_convert import origins
from .conftest import HEY, record_sim


@pytest.fixture(scope="module")
def with_views(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, Any, dict[str, Any], list[Any]]:
    """A recording with the Foxglove views (a feature processor beside the robot), the
    recorder's stats, and what the bus carried on the joint keys meanwhile."""
    path = tmp_path_factory.mktemp("fox") / "pepper.mcap"
    network = Network()
    try:
        network.start(Features(FeaturesConfig(robots="pepper"), name="features"))
        recorder, reference = record_sim(network, path, frames=150, foxglove=True)
    finally:
        network.close()
    return path, read(path), dict(recorder.stats), reference


def read(path: Any) -> tuple[dict[str, Any], dict[str, list[tuple[int, dict[str, Any]]]]]:
    """The file's channels (topic → (schema name, encoding, schema data, message encoding)) and messages."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].encoding,
                              summary.schemas[c.schema_id].data, c.message_encoding)
                    for c in summary.channels.values() if c.schema_id}
        by_topic = defaultdict(list)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            by_topic[channel.topic].append((message.log_time, from_data(channel.message_encoding, message.data)))
    return channels, by_topic


def test_every_view_has_its_schema_and_its_messages_fit_it(with_views):
    _, (channels, messages), stats, _ = with_views
    assert {"pepper/frame", "pepper/log", "pepper/tf", "pepper/info/derived"} <= channels.keys()
    expected = {"pepper/log": ("foxglove.Log", foxglove.load("foxglove.Log")),
                "pepper/tf": ("foxglove.FrameTransforms", foxglove.load("foxglove.FrameTransforms")),
                "pepper/frame": ("sonibus.v1.frame", schemas.load("frame")),
                "pepper/info/derived": ("sonibus.v1.derived_info", schemas.load("derived_info"))}
    for topic, (name, schema) in expected.items():
        found_name, encoding, data, message_encoding = channels[topic]
        assert (found_name, encoding, message_encoding) == (name, "jsonschema", "json"), topic
        assert json.loads(data) == schema, f"{topic}: not the published schema"
        assert messages[topic], f"nothing on {topic}"
        for _, message in messages[topic][:5] + messages[topic][-5:]:
            jsonschema.validate(message, json.loads(data))
    # (pepper/frame is the joints' own channel since issue 35, not a view: counted as the joints it holds)
    assert stats["foxglove"] == sum(len(messages[t]) for t in expected if t != "pepper/frame")
    assert stats["written"] == sum(len(d["names"]) if t in ("pepper/frame", "pepper/derived") else 1
                                   for t, m in messages.items() if t not in expected or t == "pepper/frame"
                                   for _, d in m)
    assert not any(t.startswith("pepper/joints/") for t in messages)


def test_frames_whole_and_transforms_at_the_fk_hand_positions(with_views):
    _, (_, messages), _, reference = with_views
    frames = messages["pepper/frame"]
    joints: dict[int, dict[str, float]] = defaultdict(dict)
    for key, sample in reference:  # what the joint keys carried on the bus
        if key.startswith("pepper/joints/"):
            joints[sample["seq"]][key.rpartition("/")[2]] = sample["v"]
    assert len(frames) >= 140
    compared = [f for _, f in frames if len(joints.get(f["seq"], ())) == 17]  # (the watcher may miss an end's)
    assert len(compared) >= len(frames) - 2
    for frame in compared:  # the frame whole: every joint, as its joint keys carried it
        assert len(frame["names"]) == 17 and dict(zip(frame["names"], frame["v"], strict=True)) == joints[frame["seq"]]
    # every frame after the robot's info has its transforms, logged with it
    transforms = dict(messages["pepper/tf"])
    info_at = messages["pepper/info"][0][0]
    later = [(log_ns, frame) for log_ns, frame in frames if log_ns > info_at]
    assert len(later) >= 140 - 10 and all(log_ns in transforms for log_ns, _ in later)
    arms = load_arms("pepper")
    moved = 0
    for log_ns, frame in later[::10]:
        angles = dict(zip(frame["names"], frame["v"], strict=True))
        found = origins(transforms[log_ns], "pepper/Torso")
        for side, hand in zip("LR", arms.hands(angles), strict=True):
            assert np.allclose(found[f"pepper/{side}Hand"], hand, atol=1e-9)
        moved += not np.allclose(arms.hands(angles), arms.hands({}))
    assert moved, "the arms never left their zero pose: nothing was checked"


def test_the_log_says_what_happened(with_views):
    _, (_, messages), _, _ = with_views
    lines = [(m["name"], m["message"], m["level"]) for _, m in messages["pepper/log"]]
    assert ("pepper/behavior", f"behavior {HEY} started", 2) in lines
    assert ("pepper/speech", 'speech "hello there" started', 2) in lines
    assert ("pepper/command", "command behavior/run ok", 2) in lines
    events = [e for topic, found in messages.items() if topic.startswith("pepper/events/") for _, e in found]
    assert len(lines) == len(events)
    stamps = sorted((m["timestamp"]["sec"], m["timestamp"]["nsec"]) for _, m in messages["pepper/log"])
    assert stamps == sorted((int(e["t"]), round((e["t"] - int(e["t"])) * 1e9)) for e in events)


def test_info_derived_holds_units_and_ranges(with_views):
    _, (_, messages), _, _ = with_views
    (_, derived), *_ = messages["pepper/info/derived"]
    entries = {d["name"]: d for d in derived["derived"]}
    assert entries["velocity/HeadYaw"]["unit"] == "rad/s" and entries["velocity/HeadYaw"]["max"] > 0
    assert derived["processor"]["node"] == "features"


def test_bus_readers_do_not_see_the_views(with_views, tmp_path, net):
    path, _, _, _ = with_views
    with Recording(str(path)) as recording:
        assert recording.views == ["pepper/info/derived", "pepper/log", "pepper/tf"]  # (frame: the joints')
        assert not set(recording.views) & set(recording.keys)
        assert all(k.startswith(("pepper/joints/", "pepper/events/", "pepper/derived/")) or k == "pepper/info"
                   for k in recording.keys)
        written = export_csv(recording, str(tmp_path / "csv"))
    assert sorted(p.rpartition("/")[2] for p in written) == ["events.csv", "pepper-derived.csv", "pepper.csv"]
    replay = net.start(Replay(ReplayConfig(path=str(path), rename={"pepper": "take1"}), name="replay"))
    assert replay.keys == recording.keys, "replay would put views on the bus as robot data"


def test_without_foxglove_there_are_no_views(tmp_path):
    network = Network()
    try:
        recorder, _ = record_sim(network, tmp_path / "plain.mcap", frames=20, foxglove=False)
    finally:
        network.close()
    channels, _ = read(tmp_path / "plain.mcap")
    assert all(name.startswith("sonibus.v1.") for name, *_ in channels.values())
    assert "foxglove" not in recorder.stats


def test_sonibus_record_writes_the_views_unless_told_not_to(net, tmp_path):
    path = tmp_path / "cli.mcap"
    net.sim("pepper", rate_hz=50)
    plain = run_cli("record", str(tmp_path / "plain.mcap"), *net.cli_args(), "--no-foxglove", "--duration", "1")
    assert plain.returncode == 0, plain.stderr
    assert "pepper/tf" not in read(tmp_path / "plain.mcap")[0]
    done = run_cli("record", str(path), *net.cli_args(), "--duration", "2")
    assert done.returncode == 0, done.stderr
    channels, messages = read(path)
    assert channels["pepper/tf"][0] == "foxglove.FrameTransforms" and messages["pepper/tf"]
    assert channels["pepper/frame"][0] == "sonibus.v1.frame" and messages["pepper/frame"]


def test_a_put_on_info_derived_does_not_kill_a_recorder_without_views(net, tmp_path):
    """``<robot>/info/derived`` reaches a recorder's queue as an answer its views asked
    for; put on the bus to a recorder of everything without views, it once went to the
    views that are not there (the writer thread died): now the gate takes it like any key."""
    recorder = net.start(Recorder(RecorderConfig(path=str(tmp_path / "all.mcap"), subscribe=("**",),
                                                 foxglove=False), name="logger"))
    bus = net.bus("script")
    wait_for(lambda: (bus.put("toy/info/derived", {"robot": "toy", "derived": "nonsense"}) or True)
             and recorder.stats["received"] >= 1, what="the put reaching the recorder")
    bus.put("toy/events/done", {"t": 1.7e9, "kind": "done"})
    wait_for(lambda: recorder.stats["written"] >= 1, what="the next event written")
    assert recorder.state == "running" and recorder.stats["bad"] >= 1


def test_the_transforms_are_written_as_their_json_byte_for_byte_moving_or_still():
    """The tf view's JSON keeps the text of a transform that did not move (issue 35: it was the
    recorder's largest per-frame cost); what it writes is ``to_json``'s, to the bit: a joint
    at 0.0 then -0.0 (equal numbers, two texts), still, moving, every joint at once."""
    import math
    import random

    from sonibus.adapters.foxglove.convert import ArmFrames
    from sonibus.adapters.recorder.channels import to_data, to_json
    from sonibus.bus.robot import load_model
    names, arms, rng = list(load_model("pepper").joint_names), ArmFrames.of("pepper"), random.Random(35)
    frames = [[0.0] * len(names), [-0.0] * len(names), [-0.0] * len(names)]  # (still, then the sign of zero)
    frames += [[math.sin(k / 7) if name.endswith("ShoulderPitch") else 0.3 for name in names] for k in range(20)]
    frames += [[rng.choice((0.0, -0.0, rng.uniform(-2, 2))) for _ in names] for _ in range(60)]
    for k, values in enumerate(frames):
        message = arms.transforms("pepper", {"t": 1.7e9 + k / 50, "seq": k, "names": names, "v": values})
        assert to_data("pepper/tf", message) == to_json(message), f"frame {k}"
    odd = {"transforms": [{**message["transforms"][0], "translation": {"x": 1, "y": 0.0, "z": 0.0}}]}
    assert to_data("pepper/tf", odd) == to_json(odd)  # (an int's text is not its float's)
    with pytest.raises(ValueError):
        to_data("pepper/tf", arms.transforms("pepper", {"t": 1.7e9, "seq": 0, "names": names,
                                                       "v": [math.nan] * len(names)}))
