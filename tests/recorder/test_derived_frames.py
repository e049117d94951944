"""Issue 35: derived values are recorded as they travel, one MCAP message per derived frame
(``<robot>/derived``), and read back as the samples of their own keys — export, replay and
``sonibus info`` give what a recording made before (one channel per derived key) gave.
``data/derived-per-key-75891cf.mcap`` is such a recording, made by sonibus at 75891cf
(sim pepper at 50 Hz running Hey_1, features, recorder; ~1.5 s)."""

from __future__ import annotations

import filecmp
import os
import threading
from pathlib import Path

from sonibus.adapters.features import Features, FeaturesConfig
from sonibus.adapters.recorder.reading import Recording
from sonibus.adapters.recorder.replay import Replay, ReplayConfig
from sonibus.adapters.recorder.writer import RecordingWriter
from sonibus.bus import decode, framing

from ..conftest import wait_for
from .conftest import record_sim, settle
from .test_export import export, ns, t_of, value, write_frame, write_info

OLD = Path(__file__).parent / "data" / "derived-per-key-75891cf.mcap"
NAMES = ["velocity/HeadYaw", "hand/R", "qom/Body"]


def derived_values(seq: int) -> list:
    return [value(seq, 99), [seq / 3, -seq / 7, 0.5], abs(value(seq, 5))]


def write(path: str, framed: bool) -> str:
    """Five frames of joints and three derived values, as derived frames or on their own keys
    (frame 2 without hand/R, as a processor leaves out a value that is not finite)."""
    with RecordingWriter(path) as out:
        write_info(out)
        for seq in range(5):
            write_frame(out, seq)
            t = t_of(seq)
            names, values = zip(*[(n, v) for n, v in zip(NAMES, derived_values(seq), strict=True)
                                  if not (seq == 2 and n == "hand/R")], strict=True)
            frame = framing.derived_frame(t, seq, names, values)
            if framed:
                out.write("pepper/derived", ns(t), frame)
            else:
                for name, sample in framing.derived_samples(frame):
                    out.write(f"pepper/derived/{name}", ns(t), sample)
    return path


def test_a_file_of_derived_frames_reads_and_exports_as_one_of_derived_keys(tmp_path):
    framed, per_key = write(str(tmp_path / "framed.mcap"), True), write(str(tmp_path / "keys.mcap"), False)
    with Recording(framed) as new, Recording(per_key) as old:
        assert new.keys == old.keys and "pepper/derived/hand/R" in new.keys
        assert new.counts == old.counts and new.counts["pepper/derived/hand/R"] == 4
        assert new.message_count == old.message_count == sum(1 for _ in new.messages())
        wanted = ["pepper/derived/hand/R", "pepper/joints/HeadYaw"]
        for keys in (None, wanted, new.matching(["pepper/derived/qom/*"])):
            assert [(m.key, m.data) for m in new.messages(keys)] == [(m.key, m.data) for m in old.messages(keys)]
        assert next(m.key for m in new.messages(start_s=0.05)) == "pepper/joints/HeadYaw"
    (new_csv, new_derived), (old_csv, old_derived) = export(framed, str(tmp_path / "a")), \
        export(per_key, str(tmp_path / "b"))
    assert os.path.basename(new_derived) == "pepper-derived.csv"
    assert filecmp.cmp(new_derived, old_derived, shallow=False) and filecmp.cmp(new_csv, old_csv, shallow=False)


def test_the_recorder_writes_one_message_per_derived_frame_and_reads_back_their_values(net, tmp_path):
    watch = net.bus("watcher")
    seen: list[tuple[str, dict]] = []
    lock = threading.Lock()

    def take(sample) -> None:
        with lock:
            seen.append((str(sample.key_expr), decode(sample.payload.to_bytes())))

    subscriber = watch.session.declare_subscriber("pepper/derived/**", take)
    features = net.start(Features(FeaturesConfig(robots="pepper", max_age_ms=0), name="features"))
    path = tmp_path / "new.mcap"
    record_sim(net, path, frames=30, foxglove=False)
    settle(lambda: len(seen))
    features.stop()
    subscriber.undeclare()
    on_bus = [(f"{key}/{name}", sample) for key, frame in seen for name, sample in framing.derived_samples(frame)]
    assert {key for key, _ in seen} == {"pepper/derived"}
    with Recording(str(path)) as recording:
        assert recording._counts["pepper/derived"] == len(seen)  # one MCAP message a frame, as it came
        assert not any(k.startswith("pepper/derived/") for k in recording._counts)
        read = [(m.key, m.data) for m in recording.messages() if m.key.startswith("pepper/derived/")]
    assert read == on_bus and len(read) > 20 * len(seen) > 0
    replayed: list[tuple[str, dict]] = []
    subscriber = watch.session.declare_subscriber("pepper/derived/**", lambda s: replayed.append(
        (str(s.key_expr), decode(s.payload.to_bytes()))))
    replay = net.start(Replay(ReplayConfig(path=str(path), speed=4.0, keys=("pepper/derived/qom/*",)), name="replay"))
    wait_for(lambda: len(replayed) >= 10, what="derived frames replayed")
    replay.stop()
    subscriber.undeclare()
    assert {key for key, _ in replayed} == {"pepper/derived"}  # as they were recorded: a frame each
    recorded = {(name, tuple(m["v"] for k, m in on_bus if k == f"pepper/derived/{name}")) for name in
                {n for _, f in replayed for n in f["names"]}}
    assert all(f["names"] and all(n.startswith("qom/") for n in f["names"]) for _, f in replayed)
    assert all(v in dict(recorded)[n] for _, f in replayed for n, v in zip(f["names"], f["v"], strict=True))


def test_a_recording_made_before_derived_frames_still_reads_exports_and_replays(net, tmp_path):
    with Recording(str(OLD)) as recording:
        derived = [k for k in recording.keys if k.startswith("pepper/derived/")]
        assert len(derived) == 26 and "pepper/derived/qom/Body" in derived
        recorded: dict[str, list] = {}
        for m in recording.messages(derived):
            recorded.setdefault(m.key, []).append(m.data["v"])
    paths = export(str(OLD), str(tmp_path / "csv"))
    assert [os.path.basename(p) for p in paths][:2] == ["pepper.csv", "pepper-derived.csv"]
    header = Path(paths[1]).read_text(encoding="utf-8").splitlines()[0]
    assert "qom/Body" in header and "hand/R.2" in header
    watch = net.bus("watcher")
    got: list[tuple[str, object]] = []
    subscriber = watch.session.declare_subscriber("pepper/derived/**", lambda s: got.append(
        (str(s.key_expr), decode(s.payload.to_bytes())["v"])))
    replay = net.start(Replay(ReplayConfig(path=str(OLD), speed=4.0), name="replay"))
    wait_for(lambda: {k for k, _ in list(got)} == set(derived), what="every derived key replayed")
    replay.stop()
    subscriber.undeclare()
    assert all(v in recorded[key] for key, v in got)  # each value as recorded (its seq: the replay's own)
