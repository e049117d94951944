"""CSV export: a row per frame in the robot's joint order, values as recorded, derived values and events apart."""

from __future__ import annotations

import csv
import json
import math
import os

import pytest

from sonibus.adapters.recorder.export import export_csv
from sonibus.adapters.recorder.reading import Recording
from sonibus.adapters.recorder.writer import RecordingWriter
from sonibus.bus import load_model

T0 = 1_700_000_000.123456
RATE_HZ = 50.0
PEPPER = load_model("pepper")


def t_of(seq: int) -> float:
    return T0 + seq / RATE_HZ


def value(seq: int, joint: int) -> float:
    """A position with all of a float's digits, so a lossy export shows."""
    return math.sin(0.1 * seq + joint) / 3


LOG_DELAY_S = 0.001  # the recorder gets a message 1 ms after its acquisition


def ns(t: float) -> int:
    return int(t * 1e9) + int(LOG_DELAY_S * 1e9)


def times(seq: int) -> list[str]:
    """A row's t_s and t_unix_s in a recording that starts with frame 0 (its first log time)."""
    return [repr(round(t_of(seq) - ns(t_of(0)) / 1e9, 6)), repr(t_of(seq))]


def write_info(out: RecordingWriter, robot: str = "pepper", model: str = "pepper") -> None:
    joints = load_model(model).joints
    out.write(f"{robot}/info", ns(T0), {"robot": robot, "model": model, "joints": [j.to_info() for j in joints],
                                        "rate_hz": RATE_HZ, "behaviors": [], "postures": [], "adapter": "sim",
                                        "schema_version": 1, "owner": {"host": "test", "node": "test"}})


def write_frame(out: RecordingWriter, seq: int, robot: str = "pepper", model: str = "pepper",
                skip: tuple[str, ...] = ()) -> None:
    for j, joint in enumerate(load_model(model).joints):
        if joint.name not in skip:
            out.write(f"{robot}/joints/{joint.name}", ns(t_of(seq)),
                      {"t": t_of(seq), "seq": seq, "v": value(seq, j), "cmd": 0.0, "temp": 30.0})


def write_event(out: RecordingWriter, seq: int, kind: str, robot: str = "pepper", **fields: object) -> None:
    out.write(f"{robot}/events/{kind}", ns(t_of(seq)), {"t": t_of(seq), "kind": kind, **fields})


SPEECH = "Hello there, I am Pepper and I am very happy to meet you"


def record(path: str, frames: int = 10, info: bool = True, events: bool = True, skip: dict[int, str] | None = None,
           behavior_stops: bool = True) -> str:
    """A pepper recording: ``frames`` frames of its 17 joints (without ``skip[seq]``), an info, a few events."""
    skip = skip or {}
    with RecordingWriter(path) as out:
        if info:
            write_info(out)
        for seq in range(frames):
            write_frame(out, seq, skip=(skip[seq],) if seq in skip else ())
            if not events:
                continue
            if seq == 1:
                write_event(out, seq, "posture", name="StandInit", state="started")
                write_event(out, seq, "command", verb="say", args={"text": "hi"}, ok=True)
            elif seq == 2:
                write_event(out, seq, "behavior", name="animations/Stand/Gestures/Hey_1", state="started")
            elif seq == 3:
                write_event(out, seq, "speech", text=SPEECH, state="started")
            elif seq == 5:
                write_event(out, seq, "posture", name="StandInit", state="reached")
            elif seq == 6 and behavior_stops:
                write_event(out, seq, "behavior", name="animations/Stand/Gestures/Hey_1", state="stopped")
            elif seq == 7:
                write_event(out, seq, "speech", text=SPEECH, state="done")
    return path


def export(path: str, directory: str) -> list[str]:
    with Recording(path) as recording:
        return export_csv(recording, directory)


def rows(path: str) -> list[list[str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.reader(f))


def test_a_row_per_frame_with_the_joints_in_the_info_order(tmp_path):
    paths = export(record(str(tmp_path / "r.mcap"), frames=12), str(tmp_path / "out" / "csv"))
    assert paths == [str(tmp_path / "out" / "csv" / "pepper.csv"), str(tmp_path / "out" / "csv" / "events.csv")]
    header, *table = rows(paths[0])
    assert header == ["t_s", "t_unix_s", "seq", *PEPPER.joint_names]
    assert len(PEPPER.joint_names) == 17
    assert len(table) == 12
    assert [int(row[2]) for row in table] == list(range(12))


def test_values_and_times_come_back_exactly(tmp_path):
    paths = export(record(str(tmp_path / "r.mcap")), str(tmp_path / "csv"))
    for seq, row in enumerate(rows(paths[0])[1:]):
        assert row[1] == repr(t_of(seq)) and float(row[1]) == t_of(seq)
        # issue 37, item 9: t was only the Unix time; t_s counts from the recording's start (its first log time)
        assert float(row[0]) == pytest.approx(t_of(seq) - t_of(0) - LOG_DELAY_S, abs=1e-6)
        assert [float(cell) for cell in row[3:]] == [value(seq, j) for j in range(17)]


def test_a_joint_missing_from_a_frame_leaves_its_cell_empty(tmp_path):
    paths = export(record(str(tmp_path / "r.mcap"), skip={3: "LHand"}), str(tmp_path / "csv"))
    header, *table = rows(paths[0])
    column = header.index("LHand")
    assert table[3][column] == ""
    assert all(cell != "" for i, cell in enumerate(table[3]) if i != column)
    assert all(row[column] != "" for seq, row in enumerate(table) if seq != 3)


def test_without_an_info_the_joints_go_by_name(tmp_path):
    paths = export(record(str(tmp_path / "r.mcap"), info=False), str(tmp_path / "csv"))
    assert rows(paths[0])[0] == ["t_s", "t_unix_s", "seq", *sorted(PEPPER.joint_names)]


def test_a_robot_counting_again_from_zero_starts_new_frames(tmp_path):
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        for seq in (4, 5, 0, 1):
            write_frame(out, seq)
    table = rows(export(path, str(tmp_path / "csv"))[0])[1:]
    assert [row[2] for row in table] == ["4", "5", "0", "1"]


def test_events_of_all_robots_in_one_file(tmp_path):
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        write_frame(out, 0)
        write_event(out, 0, "behavior", name="animations/Stand/Gestures/Hey_1", state="started")
        write_event(out, 1, "speech", robot="nao", text="bonjour", state="started")
        write_event(out, 2, "command", verb="posture", args={"name": "Crouch", "speed": 0.5}, ok=False,
                    error="unknown_posture")
        write_event(out, 3, "connection", robot="nao", state="lost")
    paths = export(path, str(tmp_path / "csv"))
    assert [os.path.basename(p) for p in paths] == ["pepper.csv", "events.csv"]
    assert rows(paths[1]) == [
        ["t_s", "t_unix_s", "robot", "kind", "state", "name", "text", "details"],
        [*times(0), "pepper", "behavior", "started", "animations/Stand/Gestures/Hey_1", "", ""],
        [*times(1), "nao", "speech", "started", "", "bonjour", ""],
        [*times(2), "pepper", "command", "", "", "",
         json.dumps({"args": {"name": "Crouch", "speed": 0.5}, "error": "unknown_posture", "ok": False,
                     "verb": "posture"})],
        [*times(3), "nao", "connection", "lost", "", "", ""],
    ]
    assert json.loads(rows(paths[1])[3][7])["args"] == {"name": "Crouch", "speed": 0.5}


def test_no_events_no_events_file(tmp_path):
    paths = export(record(str(tmp_path / "r.mcap"), events=False), str(tmp_path / "csv"))
    assert [os.path.basename(p) for p in paths] == ["pepper.csv"]
    assert sorted(os.listdir(tmp_path / "csv")) == ["pepper.csv"]


def test_derived_values_get_their_own_file_only_when_recorded(tmp_path):
    assert "pepper-derived.csv" not in os.listdir(os.path.dirname(export(record(str(tmp_path / "plain.mcap")),
                                                                         str(tmp_path / "plain"))[0]))
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        for seq in range(5):
            write_frame(out, seq)
            t = t_of(seq)
            out.write("pepper/derived/velocity/HeadYaw", ns(t), {"t": t, "seq": seq, "v": value(seq, 99)})
            if seq != 2:
                out.write("pepper/derived/hand/RHand", ns(t), {"t": t, "seq": seq, "v": [seq / 3, -seq / 7, 0.5]})
    paths = export(path, str(tmp_path / "csv"))
    assert [os.path.basename(p) for p in paths] == ["pepper.csv", "pepper-derived.csv"]
    header, *table = rows(paths[1])
    assert header == ["t_s", "t_unix_s", "seq", "hand/RHand.0", "hand/RHand.1", "hand/RHand.2", "velocity/HeadYaw"]
    assert len(table) == 5
    assert table[2] == [*times(2), "2", "", "", "", repr(value(2, 99))]
    assert [float(c) for c in table[4][3:]] == [4 / 3, -4 / 7, 0.5, value(4, 99)]


def test_two_robots_two_files(tmp_path):
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        write_info(out, "nao", "nao")
        for seq in range(6):  # interleaved, as they come on the bus
            write_frame(out, seq)
            write_frame(out, seq + 100, robot="nao", model="nao", skip=("RHand",) if seq == 4 else ())
    paths = export(path, str(tmp_path / "csv"))
    assert [os.path.basename(p) for p in paths] == ["nao.csv", "pepper.csv"]
    nao, pepper = rows(paths[0]), rows(paths[1])
    assert nao[0] == ["t_s", "t_unix_s", "seq", *load_model("nao").joint_names]
    assert pepper[0] == ["t_s", "t_unix_s", "seq", *sorted(PEPPER.joint_names)]  # no pepper info recorded
    assert [row[2] for row in nao[1:]] == [str(seq + 100) for seq in range(6)]
    assert len(pepper) == 7
    assert nao[5][nao[0].index("RHand")] == "" and nao[5][nao[0].index("LHand")] != ""
