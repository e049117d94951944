"""A picture of a recording: joint positions, one panel per chain and robot, under
behaviors and speech (shaded spans, each with an edge where it starts, and labels
that step down when they would overprint), postures (vertical lines) and
``joints/set`` commands (a tick on the panels of the joints they moved). Needs
matplotlib.

>>> import os, tempfile
>>> from sonibus.adapters.recorder.reading import Recording
>>> from sonibus.adapters.recorder.writer import RecordingWriter
>>> path = os.path.join(tempfile.mkdtemp(), "doc.mcap")
>>> with RecordingWriter(path) as out:
...     for seq in range(20):
...         out.write("pepper/joints/HeadYaw", seq * 10**7, {"t": 1.7e9 + seq / 100, "seq": seq, "v": seq / 20})
...     out.write("pepper/events/behavior", 5 * 10**7, {"t": 1.7e9 + 0.05, "kind": "behavior",
...                                                    "name": "animations/Stand/Gestures/Hey_1", "state": "started"})
>>> with Recording(path) as recording:
...     os.path.basename(plot(recording, path.replace(".mcap", ".png")))
'doc.png'
"""

from __future__ import annotations

import logging
import os
from array import array
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from .reading import Recording, RecordingError

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

UNITS = {"rad": "rad", "fraction": "open 0..1"}
SPANS = {"behavior": {"color": "tab:orange", "alpha": 0.15}, "speech": {"color": "tab:blue", "alpha": 0.12}}
MARKED = ("behavior", "speech", "posture", "command")
LABEL_ROWS = 3       # label heights a run of close spans steps through
CLOSE = 0.08         # spans starting within this fraction of the plot's width are close
MAX_PANELS = 24      # panels in one picture (a robot's chains: Pepper 5; a file may name thousands of robots)
MAX_LINES = 256      # joints drawn in one picture (Pepper 17, NAO 26)
MAX_MARKS = 500      # events marked, of each robot (20,000 took matplotlib minutes and GBs)
MAX_POINTS = 1 << 20  # samples drawn, of all joints: a longer recording is thinned (an hour of Pepper: 6 M)
MIN_POINTS = 4096    # samples drawn of one joint, however many joints

log = logging.getLogger(__name__)


def plot(recording: Recording, out: str, keys: Sequence[str] | None = None, title: str | None = None) -> str:
    """Draw ``recording`` into the image ``out`` (its format from the extension); returns ``out``.
    ``keys`` (key expressions) choose the joints; the events of their robots are always marked."""
    figure(recording, keys, title).savefig(out, dpi=120)
    return out


def figure(recording: Recording, keys: Sequence[str] | None = None, title: str | None = None) -> Figure:
    """The matplotlib figure ``plot`` saves; ``RecordingError`` if there is no joint nor event to draw."""
    try:  # a bare Figure renders without pyplot, so no backend is chosen for the caller
        from matplotlib.figure import Figure
    except ImportError:
        raise RecordingError("sonibus plot needs matplotlib: pip install matplotlib "
                             "(in a clone of sonibus: .venv/bin/pip install -e '.[plot]')") from None

    chosen = recording.matching(keys) if keys else recording.keys
    joints = [k for k in chosen if _section(k) == "joints"]
    robots = sorted({_robot(k) for k in joints or [k for k in chosen if _section(k) == "events"]})
    events = [k for k in recording.keys if _robot(k) in robots and _section(k) == "events"
              and k.rsplit("/", 1)[1] in MARKED]
    if not robots:
        raise RecordingError(f"nothing to plot in {recording.path}: no joint nor event key among "
                             f"{', '.join(chosen[:8])}{', ...' if len(chosen) > 8 else ''}")
    infos = recording.infos()
    panels = [(robot, *panel) for robot in robots
              for panel in _panels([k for k in joints if _robot(k) == robot], infos.get(robot))]
    if len(panels) > MAX_PANELS or len(joints) > MAX_LINES:  # (matplotlib took minutes and GBs over thousands)
        raise RecordingError(f"{recording.path}: too much for one picture ({len(joints)} joints in {len(panels)} "
                             f"panels; at most {MAX_LINES} joints in {MAX_PANELS} panels) — choose some with --keys, "
                             f"e.g. --keys '{robots[0]}/joints/*'")
    series = {k: _Series(max(MIN_POINTS, MAX_POINTS // len(joints))) for k in joints}
    happened: dict[str, list[tuple[float, dict[str, Any]]]] = {robot: [] for robot in robots}
    unmarked = 0
    for message in recording.messages(joints + events):
        x = (message.publish_ns - recording.start_ns) / 1e9
        if message.key in series:
            series[message.key].add(x, message.data["v"])
        elif len(happened[_robot(message.key)]) < MAX_MARKS:
            happened[_robot(message.key)].append((x, message.data))
        else:
            unmarked += 1
    if unmarked:
        log.warning("%s: %d events not marked: a picture marks at most the first %d of a robot",
                    recording.path, unmarked, MAX_MARKS)
    # acquisition precedes logging: the first samples can lie just before the start
    begin = min([0.0, *(line.x[0] for line in series.values() if line.x)])
    end = max([recording.duration_s, *(line.x[-1] for line in series.values() if line.x)])

    fig = Figure(figsize=(11, 1.2 + 2.0 * len(panels)), dpi=120, layout="constrained")
    axes = list(fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0])
    for ax, (robot, chain, names, units) in zip(axes, panels, strict=True):
        for name in names:
            line = series[f"{robot}/joints/{name}"]
            ax.plot(line.x, line.y, lw=1, label=name)
        label = f"{robot} {chain}" if len(robots) > 1 else chain
        ax.set_ylabel(f"{label}\n{units}" if units else label, fontsize=8)
        if names:
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.005, 1), frameon=False)
        else:
            ax.set_yticks([])
    for robot in robots:
        mine = [(ax, panel[2]) for ax, panel in zip(axes, panels, strict=True) if panel[0] == robot]
        _mark(mine, happened[robot], end, end - begin)
    axes[-1].set_xlim(begin, end)
    axes[-1].set_xlabel("s since the recording start")
    fig.suptitle(title or f"{os.path.basename(recording.path)} — {recording.duration_s:.1f} s — {', '.join(robots)}")
    return fig


class _Series:
    """A joint's samples as drawn: at most ``2 * most``, thinned as they come (every
    other one dropped, then every fourth...), in arrays (8 bytes a value).

    >>> line = _Series(most=4)
    >>> for i in range(20):
    ...     line.add(i, -i)
    >>> list(line.x), list(line.y)
    ([0.0, 4.0, 8.0, 12.0, 16.0], [0.0, -4.0, -8.0, -12.0, -16.0])
    """

    def __init__(self, most: int) -> None:
        self.x, self.y = array("d"), array("d")
        self._most, self._step, self._seen = most, 1, 0

    def add(self, x: float, y: float) -> None:
        if self._seen % self._step == 0:
            self.x.append(x)
            self.y.append(y)
            if len(self.x) >= 2 * self._most:
                self.x, self.y, self._step = self.x[::2], self.y[::2], 2 * self._step
        self._seen += 1


def _section(key: str) -> str:
    parts = key.split("/")
    return parts[1] if len(parts) >= 3 else ""


def _robot(key: str) -> str:
    return key.partition("/")[0]


def _panels(keys: list[str], info: dict[str, Any] | None) -> list[tuple[str, list[str], str]]:
    """(chain, joints, unit label) of each panel of a robot, in its info's order; one "joints" panel without info."""
    names = {k.split("/", 2)[2] for k in keys}
    if not names:
        return [("events", [], "")]
    chains: dict[str, list[str]] = {}
    units: dict[str, list[str]] = {}
    for joint in (info or {}).get("joints", []):
        if joint.get("name") in names:
            chain = joint.get("chain") or "other"
            chains.setdefault(chain, []).append(joint["name"])
            unit = UNITS.get(joint.get("unit"), joint.get("unit", ""))
            if unit not in units.setdefault(chain, []):
                units[chain].append(unit)
    rest = sorted(names - {n for group in chains.values() for n in group})
    if rest:
        chains["joints" if not chains else "other"] = rest
    return [(chain, group, ", ".join(units.get(chain, []))) for chain, group in chains.items()]


def _mark(panels: list[tuple[Axes, list[str]]], events: list[tuple[float, dict[str, Any]]], end: float,
          width: float) -> None:
    """Behaviors and speech as spans (an unclosed one lasts to ``end``), postures as lines,
    ``joints/set`` as ticks on the panels of its joints; labels on the top panel."""
    axes = [ax for ax, _ in panels]
    spans: list[tuple[str, float, float, str]] = []
    running: dict[str, float] = {}
    speaking: tuple[float, str] | None = None
    for x, data in events:
        kind, state, name = data.get("kind"), data.get("state"), str(data.get("name", ""))
        if kind == "behavior":
            # a stop with no start: the behavior was running when the recording began
            if name in running or state != "started":
                spans.append(("behavior", running.pop(name, 0.0), x, name.rstrip("/").rsplit("/", 1)[-1]))
            if state == "started":
                running[name] = x
        elif kind == "speech":
            text = str(data.get("text", ""))
            text = text if len(text) <= 30 else text[:29] + "…"
            if speaking or state != "started":  # a new sentence also ends the previous one, done or not
                start, said = speaking or (0.0, text)
                spans.append(("speech", start, x, said))
            speaking = (x, text) if state == "started" else None
        elif kind == "posture":
            for ax in axes:
                ax.axvline(x, color="tab:green", lw=0.8, ls="--" if state == "started" else ":", gid="posture")
            if state == "started":
                axes[0].text(x, 0.5, name, transform=axes[0].get_xaxis_transform(), fontsize=7, rotation=90,
                             va="center", ha="left", color="tab:green", clip_on=True)
        elif kind == "command" and data.get("verb") == "joints/set" and data.get("ok"):
            moved = set((data.get("args") or {}).get("names") or ())
            for ax, names in panels:
                if moved & set(names):
                    ax.plot([x], [1.0], marker="v", ms=4, color="tab:purple", transform=ax.get_xaxis_transform(),
                            clip_on=False, gid="command")
    spans += [("behavior", x, end, name.rstrip("/").rsplit("/", 1)[-1]) for name, x in running.items()]
    spans += [("speech", speaking[0], end, speaking[1])] if speaking else []
    last: dict[str, tuple[float, int]] = {}  # kind → start and label row of its previous span
    for kind, start, stop, label in sorted(spans, key=lambda span: span[1]):
        before, row = last.get(kind, (-float("inf"), -1))
        row = (row + 1) % LABEL_ROWS if start - before < CLOSE * width else 0
        last[kind] = (start, row)
        for ax in axes:
            ax.axvspan(start, stop, gid=kind, lw=0, **SPANS[kind])
            ax.axvline(start, color=SPANS[kind]["color"], lw=0.6, alpha=0.8, gid=f"{kind}-edge")
        step = 0.1 * row
        axes[0].text(start, 0.98 - step if kind == "behavior" else 0.02 + step, label,
                     transform=axes[0].get_xaxis_transform(), fontsize=7,
                     va="top" if kind == "behavior" else "bottom", ha="left", clip_on=True)
