"""A robot's expressive descriptors frame by frame (opt-in feature ``expressive``):
what ``RobotFeatures`` calls for them, and the keys they go out on.

- per hand (``L``, ``R``), from the derivative fit of its FK point: the four
  Laban Efforts, curvature, fluidity and kinetic energy per unit mass;
- for both arms (name ``arms``), from this frame's FK points: hand-to-hand
  distance, points density of hands and elbows, left/right symmetry of the hands;
- per chain with no kinematics (Pepper's ``Head`` and ``Leg``, NAO's legs), in
  joint space from a fit of its joint angles: Weight, Time, Flow, Space,
  fluidity and the kinetic-energy proxy ½ Σ w_j q̇_j² (w: the QoM weights);
- per chain with motion events, the segment an offset closes (``segments.py``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sonibus.bus import keys

from .config import FeaturesConfig
from .kinematic import FitOperator, PointDerivatives, curvature
from .laban import LabanEfforts
from .segments import SEGMENT, SegmentRecorder
from .shape import points_density, symmetry
from .table import Robot

Values = list[tuple[str, float]]  # (key, value) of this frame

HANDS = ("laban_weight", "laban_time", "laban_flow", "laban_space", "fluidity", "kinetic_energy", "curvature")
JOINT_SPACE = HANDS[:-1]  # no curvature in joint space
BOTH = ("hand_distance", "points_density", "symmetry")
BOTH_NAME = "arms"
# a segment's values as derived values too (reachable like any: OSC, MIDI, recorder, plots), on its offset
SEGMENT_FEATURES = {v: "segment_" + v.removesuffix("_s") for v in SEGMENT}
JOINT_DISPLACEMENT = 0.01  # rad: joint-space Space under it is none (1 mrad of noise moves a fitted chain ~3 mrad)


def elbow_frame(arms_joints: tuple[tuple[str, ...], ...]) -> int | None:
    """The frame index of the elbow on every arm (the first joint named ``*Elbow*``'s), or None."""
    found = {next((i for i, j in enumerate(arm) if "Elbow" in j), None) for arm in arms_joints}
    return found.pop() if len(found) == 1 else None


def joint_chains(robot: Robot, weights: np.ndarray) -> dict[str, list[int]]:
    """The chains that no arm's kinematics covers and that weigh something: their joints."""
    arm = set() if robot.arm_joints is None else set(robot.arm_joints.ravel().tolist())
    return {c: [i for i in members if weights[i] > 0] for c, members in robot.groups.items()
            if c != "Body" and not arm & set(members) and weights[members].sum() > 0}


class Expressive:
    """The expressive descriptors of one robot; ``hands``, ``joints`` and ``record`` per frame.

    A frame's fits share one ``FitOperator`` (the hands' and the joint chains' windows hold the
    same frames), and what follows the fits is worked out in plain floats: a hand is 3 numbers,
    a chain a few angles, and numpy's cost per call is more than their arithmetic."""

    def __init__(self, robot: Robot, config: FeaturesConfig, weights: np.ndarray) -> None:
        self.robot, name = robot, robot.name
        window, fit = config.laban_window_s, config.fit_window_s
        arms = robot.arms
        operator = FitOperator(fit)
        self.sides: tuple[str, ...] = arms.sides if arms is not None else ()
        self._fit = PointDerivatives(len(self.sides), fit, operator=operator) if self.sides else None
        self._efforts = LabanEfforts(np.eye(len(self.sides)), window)  # each hand its own group
        self._hand_keys = [[keys.derived(name, f, s) for f in HANDS] for s in self.sides]
        self.elbow = elbow_frame(arms.joints) if arms is not None else None  # FK frame whose points to add
        self._pair = tuple(self.sides.index(s) for s in ("L", "R")) if set("LR") <= set(self.sides) else None
        self._both_keys = [keys.derived(name, f, BOTH_NAME) for f in BOTH]
        self.chains = joint_chains(robot, weights)
        self._joints = [i for members in self.chains.values() for i in members]
        self._joint_fit = PointDerivatives(len(self._joints), fit, dim=1, operator=operator) if self._joints else None
        # each chain one point of its angles: which of the fitted joints, and their QoM weights
        self._chain_slices: list[tuple[int, int]] = []  # where each chain's joints are among the fitted
        start = 0
        for members in self.chains.values():
            self._chain_slices.append((start, start + len(members)))
            start += len(members)
        self._chain_weights = [weights[m].tolist() for m in self.chains.values()]
        self._joint_efforts = LabanEfforts(np.eye(len(self.chains)), window, JOINT_DISPLACEMENT)
        self._joint_keys = [[keys.derived(name, f, c) for f in JOINT_SPACE] for c in self.chains]
        # motion segments: an arm chain's is its hand's path, another chain's its joints' path
        self._arm_of = {c: a for c, members in robot.chains.items() for a in range(len(self.sides))
                        if arms is not None and arms.joints[a][0] in members}
        self.segments = {c: SegmentRecorder(config.min_duration_s) for c in robot.chains}
        groups = robot.groups
        self._members = {c: list(groups[c]) for c in robot.chains}
        self._segment_keys = {c: {v: keys.derived(name, f, c) for v, f in SEGMENT_FEATURES.items()}
                              for c in robot.chains}

    def hands(self, t: float, points: np.ndarray, elbows: np.ndarray | None) -> Values:
        """The hands' descriptors from this frame's hand ``points`` (arms, 3) and elbow points
        (FK frame ``elbow``; None without)."""
        out: Values = []
        if self._pair is not None:
            rows = points.tolist()
            left, right = rows[self._pair[0]], rows[self._pair[1]]
            density = points_density(rows if elbows is None else rows + elbows.tolist())
            out += zip(self._both_keys, (math.dist(left, right), density, symmetry(left, right)), strict=True)
        fit = self._fit
        if fit is None or not fit.update(t, points):
            return out
        p, v, a, j = fit.derivatives.tolist()
        for names, efforts, vi, ai in zip(self._hand_keys, self._efforts.rows(fit.time, p, v, a, j), v, a,
                                          strict=True):
            _finite(out, names, (*efforts, 0.5 * (vi[0] * vi[0] + vi[1] * vi[1] + vi[2] * vi[2]), curvature(vi, ai)))
        return out

    def joints(self, t: float, positions: np.ndarray) -> Values:
        """The joint-space descriptors of the chains with no kinematics from all joint ``positions``."""
        out: Values = []
        fit = self._joint_fit
        if fit is None:
            return out
        q = positions[self._joints]
        if not np.isfinite(q).all() or not fit.update(t, q):
            return out
        p, v, a, j = ([x[i:k] for i, k in self._chain_slices] for x in fit.derivatives[..., 0].tolist())
        rows = self._joint_efforts.rows(fit.time, p, v, a, j)
        for names, efforts, vc, w in zip(self._joint_keys, rows, v, self._chain_weights, strict=True):
            _finite(out, names, (*efforts, 0.5 * sum(wi * x * x for wi, x in zip(w, vc, strict=True))))
        return out

    def record(self, t: float, positions: np.ndarray, hands: np.ndarray | None) -> None:
        """Add this frame to every chain's segment recorder (an arm chain's only with its hand)."""
        angles = positions.tolist()
        points = None if hands is None else hands.tolist()
        for chain, recorder in self.segments.items():
            arm = self._arm_of.get(chain)
            if arm is not None:
                if points is not None:
                    recorder.add(t, points[arm])
                continue
            q = [angles[i] for i in self._members[chain]]
            if all(map(math.isfinite, q)):
                recorder.add(t, q)

    def segment(self, chain: str, state: str, at: float) -> dict[str, Any] | None:
        """Tell ``chain``'s recorder its motion changed at ``at``; the segment an offset closes."""
        recorder = self.segments.get(chain)
        return None if recorder is None else recorder.change(state, at)

    def segment_samples(self, chain: str, segment: dict[str, float]) -> list[tuple[str, float]]:
        """``segment``'s values as ``(key, value)`` of derived values ``segment_<value>/<chain>``."""
        names = self._segment_keys[chain]
        return [(names[v], value) for v, value in segment.items()]


def _finite(out: Values, names: list[str], values: tuple[float, ...]) -> None:
    """Add ``values`` under ``names``, those not finite left out (Space with no displacement,
    κ below the speed floor: none)."""
    out += [(key, value) for key, value in zip(names, values, strict=True) if math.isfinite(value)]
