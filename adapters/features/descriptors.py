"""How each expressive descriptor is described on ``<robot>/info/derived``: its
definition as computed, source, unit, window, estimator and range, so that
OSCQuery, the page, mappings and recordings know what a value means.

>>> from sonibus.bus.robot import load_model
>>> from sonibus.adapters.features import FeaturesConfig
>>> from sonibus.adapters.features.motion import weights
>>> from sonibus.adapters.features.table import describe
>>> info = {"model": "pepper", "joints": [j.to_info() for j in load_model("pepper").joints]}
>>> robot = describe("pepper", info)
>>> w = weights([j.unit for j in robot.joints], robot.names)
>>> entries = expressive_entries(robot, FeaturesConfig(), w, [3.5, 3.5])
>>> [(e["name"], e["unit"], e.get("max")) for e in entries if e["name"].endswith("/Head")][:2]
[('laban_weight/Head', 'rad²/s²', None), ('laban_time/Head', 'rad/s²', None)]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sonibus.bus import keys

from .config import FeaturesConfig
from .expressive import BOTH, BOTH_NAME, HANDS, JOINT_SPACE, SEGMENT_FEATURES, elbow_frame, joint_chains
from .segments import SEGMENT
from .table import Robot

L_G = "Larboulette & Gibet, MOCO 2015"
# feature → (unit with L the length unit, definition, source, windowed)
DEFINITIONS: dict[str, tuple[str, str, str, bool]] = {
    "laban_weight": ("L²/s²", "max over the window of ‖v‖²", L_G, True),
    "laban_time": ("L/s²", "time-weighted mean of ‖a‖ over the window", L_G, True),
    "laban_flow": ("L/s³", "time-weighted mean of ‖j‖ (the jerk vector's norm) over the window", L_G, True),
    "laban_space": ("1", "path length over displacement in the window, ≥ 1 (directness is 1/Space); none under "
                         "1 mm (0.01 rad in joint space) of displacement", f"{L_G}; Piana et al. 2013", True),
    "fluidity": ("s", "⟨‖v‖⟩ / ⟨‖a‖⟩, time-weighted over the window; none while ⟨‖v‖⟩ is under 0.05",
                 "Burger et al. 2013 (mcfluidity)", True),
    "kinetic_energy": ("L²/s²", "½ ‖v‖² per unit mass (joint space: ½ Σ w_j q̇_j², w the QoM weights)",
                       "Camurri, Lagerlöf & Volpe 2003; PyEyesWeb KineticEnergy", False),
    "curvature": ("1/m", "‖v × a‖/‖v‖³; none under 0.05 m/s", "differential geometry", False),
    "hand_distance": ("m", "‖p_L − p_R‖ of this frame's hand points", "Camurri et al. 2003", False),
    "points_density": ("m", "(1/N) Σ ‖p_i − p̄‖ over hands and elbows (hands only without elbows)",
                       "Glowinski et al. 2011; PyEyesWeb PointsDensity", False),
    "symmetry": ("1", "1 − ‖p_L − M p_R‖ / (‖p_L‖ + ‖p_R‖ + 1e-10), clipped at 0; p in the Torso frame (origin "
                      "on the sagittal plane), M mirrors y: 1 for mirrored hands",
                 "Glowinski et al. 2011; PyEyesWeb GeometricSymmetry", False),
}
# what a value can be, in words (min/max where a number is known: a bound sinks can scale with)
RANGES = {"laban_weight": "≥ 0", "laban_time": "≥ 0", "laban_flow": "≥ 0", "laban_space": "≥ 1 (1: a straight path)",
          "fluidity": "> 0", "kinetic_energy": "≥ 0", "curvature": "≥ 0 (1/R on a circle of radius R)",
          "hand_distance": "≥ 0", "points_density": "≥ 0", "symmetry": "[0, 1] (1: mirrored hands)"}
SEGMENT_UNITS = {"duration_s": "s", "pause_s": "s", "path": "L", "peak_speed": "L/s", "directness": "1",
                 "fluidity": "s", "sparc": "1", "ldlj": "1"}
SEGMENT_DEFINITIONS = {  # value → (definition, range)
    "duration_s": ("offset crossing − onset crossing of the chain's QoM", "> 0"),
    "pause_s": ("onset crossing − the chain's previous offset crossing (none for its first segment)", "≥ 0"),
    "path": ("Σ‖Δp‖ over the segment's frames", "≥ 0"),
    "peak_speed": ("max ‖v‖ of the path resampled at the frames' median rate, central differences", "≥ 0"),
    "directness": ("displacement / path length", "[0, 1] (1: straight)"),
    "fluidity": ("⟨‖v‖⟩ / ⟨‖a‖⟩ over the segment", "> 0"),
    "sparc": ("spectral arc length of the speed profile (Balasubramanian et al. 2015; = monalysa 0.2.1)",
              "≤ 0 (about −1.4 for a smooth reach)"),
    "ldlj": ("log dimensionless jerk of the speed profile (Balasubramanian et al. 2015; = monalysa 0.2.1)",
             "< 0 (−5.3 for a minimum-jerk reach)"),
}


def _unit(unit: str, length: str) -> str:
    return unit.replace("L", length) if unit != "1" else unit


def _one(robot: Robot, feature: str, name: str, length: str, config: FeaturesConfig, estimator: str,
         low: float | None = None, high: float | None = None) -> dict[str, Any]:
    unit, definition, source, windowed = DEFINITIONS[feature]
    entry: dict[str, Any] = {"name": f"{feature}/{name}", "key": keys.derived(robot.name, feature, name),
                             "unit": _unit(unit, length), "size": 1, "definition": definition, "source": source,
                             "range": RANGES[feature]}
    if low is not None and high is not None:
        entry.update(min=round(float(low), 6), max=round(float(high), 6))
    if feature not in BOTH:
        entry["estimator"] = estimator
    if windowed:
        entry["window_s"] = config.laban_window_s
    return entry


def expressive_entries(robot: Robot, config: FeaturesConfig, weights: np.ndarray,
                       hand_bounds: list[float | None]) -> list[dict[str, Any]]:
    """The entries of the expressive descriptors of ``robot`` (``hand_bounds``: each hand's speed bound)."""
    fit = (f"degree-5 least-squares fit over {config.fit_window_s:g} s of the frames' own times, read at its "
           "middle (kinematic.py)")
    out = []
    arms = robot.arms
    if arms is not None:
        for side, bound in zip(arms.sides, hand_bounds, strict=True):
            for feature in HANDS:
                energy = feature == "kinetic_energy" and bound is not None
                out.append(_one(robot, feature, side, "m", config, f"the hand point's {fit}",
                                0.0 if energy else None, 0.5 * bound**2 if energy else None))
        if set("LR") <= set(arms.sides):
            for feature in BOTH:
                bounded = feature == "symmetry"
                out.append(_one(robot, feature, BOTH_NAME, "m", config, "", 0.0 if bounded else None,
                                1.0 if bounded else None))
            if elbow_frame(arms.joints) is None:
                out[-2]["definition"] = "(1/N) Σ ‖p_i − p̄‖ over the hands (no elbow known)"
    vmax = np.array([j.max_velocity or np.nan for j in robot.joints])
    for chain, members in joint_chains(robot, weights).items():
        for feature in JOINT_SPACE:
            energy = 0.5 * float(weights[members] @ vmax[members] ** 2) if feature == "kinetic_energy" else None
            known = energy is not None and np.isfinite(energy)
            entry = _one(robot, feature, chain, "rad", config, f"the chain's joint angles' {fit}",
                         0.0 if known else None, energy if known else None)
            entry["space"] = "joint"  # no kinematics: the chain's angles as one point
            out.append(entry)
    return out


def segment_entries(robot: Robot, chains: list[str]) -> list[dict[str, Any]]:
    """The entries of the segment values, published on an offset as ``segment_<value>/<chain>``."""
    lengths = segment_entry(robot, chains)["length"]
    return [{"name": f"{feature}/{chain}", "key": keys.derived(robot.name, feature, chain),
             "unit": _unit(SEGMENT_UNITS[value], lengths[chain]), "size": 1,
             "definition": SEGMENT_DEFINITIONS[value][0], "range": SEGMENT_DEFINITIONS[value][1],
             "window": "the segment", **({"min": 0.0, "max": 1.0} if value == "directness" else {})}
            for chain in chains for value, feature in SEGMENT_FEATURES.items()]


def segment_entry(robot: Robot, chains: list[str]) -> dict[str, Any]:
    """What the ``segment`` of an offset event holds, per chain its path's unit."""
    arm_chains = set()
    if robot.arms is not None:
        arm_chains = {c for c, members in robot.chains.items() for arm in robot.arms.joints if arm[0] in members}
    return {"values": {v: {"unit": SEGMENT_UNITS[v]} for v in SEGMENT},
            "length": {c: "m" if c in arm_chains else "rad" for c in chains},
            "definition": "from onset to offset crossing: duration, pause since the previous offset, path length, "
                          "directness, and on the path resampled at the frames' median rate: peak speed, "
                          "fluidity, SPARC and LDLJ (Balasubramanian et al. 2015); L is the chain's length unit "
                          "(a hand's m, a joint chain's rad)"}
