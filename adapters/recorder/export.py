"""CSV export of a recording: a table of frames per robot, one of derived values, one of events.

>>> import os, tempfile
>>> from sonibus.adapters.recorder.reading import Recording
>>> from sonibus.adapters.recorder.writer import RecordingWriter
>>> folder = tempfile.mkdtemp()
>>> with RecordingWriter(os.path.join(folder, "doc.mcap")) as out:
...     for seq in range(2):
...         for joint, v in (("HeadYaw", 0.1 * seq), ("HeadPitch", -0.25)):
...             t = 1.7e9 + seq / 50
...             out.write(f"pepper/joints/{joint}", int(t * 1e9) + 10**6, {"t": t, "seq": seq, "v": v})
>>> with Recording(os.path.join(folder, "doc.mcap")) as recording:
...     paths = export_csv(recording, os.path.join(folder, "csv"))
>>> [os.path.basename(p) for p in paths]
['pepper.csv']
>>> print(open(paths[0]).read().strip())
t_s,t_unix_s,seq,HeadPitch,HeadYaw
-0.001,1700000000.0,0,-0.25,0.0
0.019,1700000000.02,1,-0.25,0.1

(``t_s`` counts from the log time of the recording's first message, 1 ms after its sample.)
"""

from __future__ import annotations

import csv
import json
import os
from contextlib import ExitStack
from typing import Any, TextIO

from .reading import Recording

TIMES = ["t_s", "t_unix_s"]  # a row's time: seconds from the recording's start, and since the epoch
EVENT_COLUMNS = [*TIMES, "robot", "kind", "state", "name", "text", "details"]
EVENT_FIELDS = ("t", "kind", "state", "name", "text")  # the fields that have their own column


def export_csv(recording: Recording, directory: str) -> list[str]:
    """Write the CSV files of ``recording`` into ``directory`` (created if needed); returns their paths.

    ``<robot>.csv`` holds one row per frame (the samples sharing a ``seq``): its acquisition time ``t``
    as ``t_s`` (seconds from the recording's start: the log time of its first message, so a first
    sample taken just before it reads a few ms below 0) and ``t_unix_s`` (seconds since the epoch),
    ``seq`` and the position of each recorded joint, in the robot's info order if
    it was recorded, else by name; a joint missing from a frame leaves its cell empty. Extra quantities
    of joint samples (``cmd``, ``cur``, ``temp``) are not exported. ``<robot>-derived.csv`` does the same
    for derived values (a list value spreads over ``<feature>/<name>.0``, ``.1``...), and ``events.csv``
    lists the events of all robots, fields other than its columns as JSON in ``details``. Files without
    a row to hold are not written. Rows are written as frames complete: memory stays one frame per table.
    """
    os.makedirs(directory, exist_ok=True)
    origin = recording.start_ns / 1e9
    infos = recording.infos()
    joints: dict[str, list[str]] = {}
    derived: dict[str, list[str]] = {}
    tables: dict[tuple[str, str], _Frames] = {}
    columns: dict[str, list[str]] = {}  # derived key → its columns
    events = [k for k in recording.keys if _section(k) == "events"]
    for key in recording.keys:
        section = _section(key)
        if section == "joints":
            joints.setdefault(key.partition("/")[0], []).append(key)
        elif section == "derived":
            derived.setdefault(key.partition("/")[0], []).append(key)
            columns[key] = _derived_columns(recording, key)
    paths = []
    with ExitStack() as stack:
        def table(name: str, header: list[str]) -> _Frames:
            paths.append(os.path.join(directory, name))
            return stack.enter_context(_Frames(paths[-1], header, origin))

        for robot in recording.robots:
            if robot in joints:
                tables[robot, "joints"] = table(f"{robot}.csv", _joint_order(joints[robot], infos.get(robot)))
            if robot in derived:
                header = [c for k in derived[robot] for c in columns[k]]
                tables[robot, "derived"] = table(f"{robot}-derived.csv", header)
        if events:
            paths.append(os.path.join(directory, "events.csv"))
            events_file = stack.enter_context(open(paths[-1], "w", newline="", encoding="utf-8"))
            event_rows = csv.writer(events_file)
            event_rows.writerow(EVENT_COLUMNS)
        wanted = [k for group in (*joints.values(), *derived.values()) for k in group] + events
        for message in recording.messages(wanted):
            robot, section, name = message.key.split("/", 2)
            data = message.data
            if section == "events":
                event_rows.writerow(_event_row(robot, name, data, origin))
            elif section == "joints":
                tables[robot, section].add(data["t"], data["seq"], {name: data["v"]})
            else:
                values = data["v"] if isinstance(data["v"], list) else [data["v"]]
                cells = dict(zip(columns[message.key], values, strict=False))
                tables[robot, section].add(data["t"], data["seq"], cells)
    return paths


class _Frames:
    """One CSV of frames; a frame's row is written when a message of another ``seq`` comes, or at the end."""

    def __init__(self, path: str, columns: list[str], origin: float) -> None:
        self._file: TextIO = open(path, "w", newline="", encoding="utf-8")  # noqa: SIM115 — closed by __exit__
        self._csv = csv.writer(self._file)
        self._csv.writerow([*TIMES, "seq", *columns])
        self._origin = origin
        self._columns = columns
        self._seq: int | None = None
        self._t: float = 0.0
        self._cells: dict[str, Any] = {}

    def add(self, t: float, seq: int, cells: dict[str, Any]) -> None:
        # any other seq, not only a higher one, ends the frame: a restarted robot counts from 0 again
        if seq != self._seq:
            self._flush()
            self._seq, self._t = seq, t
        self._cells.update(cells)

    def _flush(self) -> None:
        if self._seq is not None:
            self._csv.writerow([*_times(self._t, self._origin), self._seq,
                                *(_cell(self._cells.get(c)) for c in self._columns)])
        self._seq, self._cells = None, {}

    def __enter__(self) -> _Frames:
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self._flush()
        finally:
            self._file.close()


def _section(key: str) -> str:
    parts = key.split("/")
    return parts[1] if len(parts) >= 3 else ""


def _cell(value: Any) -> str:
    return "" if value is None else repr(value)


def _joint_order(keys: list[str], info: dict[str, Any] | None) -> list[str]:
    names = {k.split("/", 2)[2] for k in keys}
    known = [j["name"] for j in (info or {}).get("joints", []) if j.get("name") in names]
    return known + sorted(names - set(known))


def _derived_columns(recording: Recording, key: str) -> list[str]:
    # the first value's length sets the columns: a feature's vector keeps its size
    first = next(iter(recording.messages([key]))).data["v"]
    column = key.split("/", 2)[2]
    return [f"{column}.{i}" for i in range(len(first))] if isinstance(first, list) else [column]


def _times(t: Any, origin: float) -> list[str]:
    """A row's ``t_s`` (rounded to the µs: a difference of two epoch times has no more) and ``t_unix_s``
    (exactly as recorded)."""
    if not isinstance(t, int | float):
        return ["", _cell(t)]
    return [repr(round(t - origin, 6)), repr(t)]


def _event_row(robot: str, kind: str, data: dict[str, Any], origin: float) -> list[str]:
    rest = {k: v for k, v in data.items() if k not in EVENT_FIELDS}
    return [*_times(data.get("t"), origin), robot, data.get("kind", kind), data.get("state", ""), data.get("name", ""),
            data.get("text", ""), json.dumps(rest, sort_keys=True, ensure_ascii=False) if rest else ""]
