"""Draw docs/img/expressive-hey-1.svg: every expressive descriptor of the features
node while the simulated Pepper plays Hey_1 (adapters/sim/offline.py, 50 Hz), with
the right arm's and the head's motion segments shaded, as docs/features.md shows it.

    .venv/bin/python scripts/expressive_plots.py        # writes docs/img/expressive-hey-1.svg
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from sonibus.adapters.features import FeaturesConfig
from sonibus.adapters.features.compute import RobotFeatures
from sonibus.adapters.features.table import describe
from sonibus.adapters.sim.offline import play
from sonibus.bus import load_model

OUT = Path(__file__).resolve().parent.parent / "docs" / "img" / "expressive-hey-1.svg"
RATE_HZ = 50.0
PANELS = (  # (title, unit, [(feature/name, label)])
    ("Laban Weight", "m²/s²", [("laban_weight/R", "right hand"), ("laban_weight/L", "left hand")]),
    ("Laban Time", "m/s²", [("laban_time/R", "right hand"), ("laban_time/L", "left hand")]),
    ("Laban Flow", "m/s³", [("laban_flow/R", "right hand")]),
    ("Laban Space", "", [("laban_space/R", "right hand")]),
    ("fluidity", "s", [("fluidity/R", "right hand")]),
    ("kinetic energy", "m²/s²", [("kinetic_energy/R", "right hand")]),
    ("curvature", "1/m", [("curvature/R", "right hand")]),
    ("arms: distance, density", "m", [("hand_distance/arms", "hand distance"),
                                      ("points_density/arms", "points density")]),
    ("symmetry", "", [("symmetry/arms", "arms")]),
    ("head, joint space", "rad/s², rad²/s²", [("laban_time/Head", "Time"), ("laban_weight/Head", "Weight")]),
)


def series() -> tuple[dict[str, tuple[list[float], list[float]]], list[dict]]:
    """Each derived value's (times, values), and the motion events."""
    model = load_model("pepper")
    info = {"model": "pepper", "joints": [j.to_info() for j in model.joints]}
    features = RobotFeatures(describe("pepper", info), FeaturesConfig(features=("motion", "expressive")))
    names = [f"pepper/joints/{n}" for n in model.joint_names]
    out: dict[str, tuple[list[float], list[float]]] = {}
    events: list[dict] = []
    for k, (t, positions) in enumerate(play(model, "animations/Stand/Gestures/Hey_1", RATE_HZ, 4.5)):
        step = features.step(t, k + 1, dict(zip(names, positions, strict=True)))
        for key, message in step.samples:
            times, values = out.setdefault(key.split("/", 2)[2], ([], []))
            times.append(t)
            values.append(message["v"])
        events += [m for _, m in step.events]
    return out, events


def draw(path: Path = OUT) -> None:
    data, events = series()
    plt.rcParams["svg.hashsalt"] = "sonibus"
    fig, axes = plt.subplots(len(PANELS), 1, figsize=(8, 1.6 * len(PANELS)), sharex=True)
    starts: dict[str, float] = {}
    spans = []
    for e in events:
        if e["state"] == "onset":
            starts[e["chain"]] = e["t"]
        elif e["chain"] in starts:
            spans.append((e["chain"], e["t"] - e["segment"]["duration_s"], e["t"]))
    for ax, (title, unit, lines) in zip(axes, PANELS, strict=True):
        for chain, begin, end in spans:
            ax.axvspan(begin, end, color="#f4d03f" if chain == "RArm" else "#aed6f1", alpha=0.3, lw=0)
        for name, label in lines:
            if name in data:
                ax.plot(*data[name], label=label, lw=1.2)
        if title == "curvature":
            ax.set_yscale("log")  # (1/R: a hand turning back on itself near the speed floor reads 1000s)
        ax.set_ylabel(unit, fontsize=8)
        ax.set_title(title, fontsize=9, loc="left")
        ax.tick_params(labelsize=7)
        if len(lines) > 1:
            ax.legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("s (Hey_1 starts at 0.5 s; shaded: the right arm's segment, yellow, the head's, blue)",
                        fontsize=8)
    fig.tight_layout()
    fig.savefig(path, metadata={"Date": None})


if __name__ == "__main__":
    draw()
    print(OUT)
