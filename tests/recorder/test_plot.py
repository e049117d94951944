"""Plots: an image file, a panel per chain and robot, behaviors and speech as spans on each panel of their robot."""

from __future__ import annotations

import sys

import matplotlib.image
import pytest

from sonibus.adapters.recorder.plot import figure, plot
from sonibus.adapters.recorder.reading import Recording, RecordingError
from sonibus.adapters.recorder.writer import RecordingWriter

from .test_export import PEPPER, SPEECH, record, write_event, write_frame, write_info

PNG = b"\x89PNG\r\n\x1a\n"
CHAINS = ["Head", "LArm", "Leg", "RArm"]  # pepper's, in its info's joint order


def draw(path: str, keys: list[str] | None = None):
    with Recording(path) as recording:
        return figure(recording, keys)


def marks(ax, gid: str) -> list:
    return [a for a in [*ax.patches, *ax.lines] if a.get_gid() == gid]


def labels(ax) -> list[str]:
    return [t.get_text() for t in ax.texts]


def test_a_png_that_reads_back(tmp_path):
    out = str(tmp_path / "r.png")
    with Recording(record(str(tmp_path / "r.mcap"))) as recording:
        assert plot(recording, out) == out
    with open(out, "rb") as f:
        assert f.read(8) == PNG
    image = matplotlib.image.imread(out)
    assert image.shape == (round((1.2 + 2.0 * len(CHAINS)) * 120), 11 * 120, 4)  # taller with more panels
    assert image.min() < image.max()  # something is drawn


def test_the_format_follows_the_extension(tmp_path):
    with Recording(record(str(tmp_path / "r.mcap"))) as recording:
        plot(recording, str(tmp_path / "r.svg"), title="my take")
    text = (tmp_path / "r.svg").read_text()
    assert "<svg" in text


def test_a_panel_per_chain_a_line_per_joint(tmp_path):
    fig = draw(record(str(tmp_path / "r.mcap"), frames=20))
    assert len(fig.axes) == len(CHAINS)
    assert [ax.get_ylabel().split("\n")[0] for ax in fig.axes] == CHAINS
    for ax, chain in zip(fig.axes, CHAINS, strict=True):
        joints = [line for line in ax.lines if line.get_gid() is None]
        assert [line.get_label() for line in joints] == list(PEPPER.chain(chain))
        assert all(len(line.get_xdata()) == 20 for line in joints)
        assert [t.get_text() for t in ax.get_legend().get_texts()] == list(PEPPER.chain(chain))
    assert fig.axes[0].get_ylabel() == "Head\nrad"
    assert fig.axes[1].get_ylabel() == "LArm\nrad, open 0..1"  # LHand is a hand: an opening
    head_yaw = fig.axes[0].lines[0]
    assert head_yaw.get_xdata()[1] - head_yaw.get_xdata()[0] == pytest.approx(1 / 50)
    assert fig.get_suptitle().startswith("r.mcap — 0.4 s — pepper")


def test_events_are_marked_on_every_panel_labels_on_the_top_one(tmp_path):
    fig = draw(record(str(tmp_path / "r.mcap"), frames=10))
    for ax in fig.axes:
        assert len(marks(ax, "behavior")) == 1
        assert len(marks(ax, "speech")) == 1
        assert len(marks(ax, "posture")) == 2  # started and reached
    behavior = marks(fig.axes[0], "behavior")[0]
    assert behavior.get_x() == pytest.approx(0.04, abs=0.002)  # frame 2 to 6 at 50 Hz
    assert behavior.get_width() == pytest.approx(0.08, abs=0.002)
    top = labels(fig.axes[0])
    assert "Hey_1" in top and "StandInit" in top
    assert SPEECH[:29] + "…" in top
    assert all(labels(ax) == [] for ax in fig.axes[1:])


def test_an_unclosed_span_lasts_to_the_end(tmp_path):
    fig = draw(record(str(tmp_path / "r.mcap"), frames=10, behavior_stops=False))
    span = marks(fig.axes[2], "behavior")[0]
    assert span.get_x() + span.get_width() == pytest.approx(fig.axes[2].get_xlim()[1])


def test_keys_choose_the_joints(tmp_path):
    fig = draw(record(str(tmp_path / "r.mcap")), ["pepper/joints/Head*", "pepper/joints/LHand"])
    assert [ax.get_ylabel() for ax in fig.axes] == ["Head\nrad", "LArm\nopen 0..1"]
    assert [line.get_label() for line in fig.axes[1].lines if line.get_gid() is None] == ["LHand"]
    assert len(marks(fig.axes[1], "behavior")) == 1  # the robot's events still show


def test_two_robots_their_panels_and_their_own_events(tmp_path):
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        write_info(out)
        write_info(out, "nao", "nao")
        for seq in range(5):
            write_frame(out, seq)
            write_frame(out, seq, robot="nao", model="nao")
        write_event(out, 2, "behavior", robot="nao", name="dance", state="started")
    fig = draw(path)
    ylabels = [ax.get_ylabel().split("\n")[0] for ax in fig.axes]
    assert ylabels == ["nao Head", "nao LArm", "nao LLeg", "nao RLeg", "nao RArm", *(f"pepper {c}" for c in CHAINS)]
    assert [len(marks(ax, "behavior")) for ax in fig.axes] == [1] * 5 + [0] * 4
    assert fig.get_size_inches()[1] == pytest.approx(1.2 + 2.0 * 9)


def test_events_alone_still_plot(tmp_path):
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        write_info(out)
        write_event(out, 0, "behavior", name="animations/Stand/Gestures/Hey_1", state="started")
        write_event(out, 3, "speech", text="hi", state="started")
        write_event(out, 9, "speech", text="hi", state="done")
    fig = draw(path)
    assert len(fig.axes) == 1 and fig.axes[0].get_ylabel() == "events"
    assert len(marks(fig.axes[0], "behavior")) == 1 and len(marks(fig.axes[0], "speech")) == 1
    with Recording(path) as recording:
        plot(recording, str(tmp_path / "r.png"))
    assert (tmp_path / "r.png").read_bytes()[:8] == PNG


def test_nothing_to_plot_is_a_clear_error(tmp_path):
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        write_info(out)
    with pytest.raises(RecordingError, match=r"nothing to plot .*pepper/info"):
        draw(path)
    with pytest.raises(RecordingError, match=r"no key .* matches nao/joints/"):
        draw(record(str(tmp_path / "other.mcap")), ["nao/joints/*"])


def test_without_matplotlib_a_clear_error(tmp_path, monkeypatch):
    for name in ("matplotlib", "matplotlib.figure"):  # makes importing them fail, even if loaded before
        monkeypatch.setitem(sys.modules, name, None)
    with Recording(record(str(tmp_path / "r.mcap"))) as recording, \
            pytest.raises(RecordingError, match=r"needs matplotlib: pip install matplotlib \(in a clone"):
        plot(recording, str(tmp_path / "r.png"))
    assert not (tmp_path / "r.png").exists()


def test_back_to_back_behaviors_stay_apart_and_joint_commands_are_ticked(tmp_path):
    """Issue 19, item 8: back-to-back behaviors merged into one block with overprinted
    labels; joints/set commands were not marked."""
    path = str(tmp_path / "r.mcap")
    with RecordingWriter(path) as out:
        write_info(out)
        for seq in range(100):  # 2 s: the two labels would start 4 % of the width apart
            write_frame(out, seq)
        for seq, name, state in ((2, "a/Hey_1", "started"), (6, "a/Hey_1", "stopped"),
                                 (6, "a/Yes_1", "started"), (10, "a/Yes_1", "stopped")):
            write_event(out, seq, "behavior", name=name, state=state)
        write_event(out, 12, "command", verb="joints/set", args={"names": ["HeadYaw"], "angles": [0.3]}, ok=True)
        write_event(out, 14, "command", verb="joints/set", args={"names": ["HeadYaw"], "angles": [9.0]}, ok=False)
    fig = draw(path)
    head, *others = fig.axes
    spans = marks(head, "behavior")
    assert len(spans) == 2 and len(marks(head, "behavior-edge")) == 2  # each starts with an edge of its own
    assert spans[0].get_x() + spans[0].get_width() == pytest.approx(spans[1].get_x())
    texts = {t.get_text(): t.get_position()[1] for t in head.texts}
    assert texts["Hey_1"] != texts["Yes_1"], "labels of close spans step down instead of overprinting"
    ticks = marks(head, "command")
    assert len(ticks) == 1 and ticks[0].get_xdata()[0] == pytest.approx(12 / 50, abs=0.002)  # the refused one: none
    assert all(marks(ax, "command") == [] for ax in others)  # only where the moved joint is drawn
