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
from .kinematic import PointDerivatives, curvature
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
    """The expressive descriptors of one robot; ``frame`` and ``record`` per frame.

    One fit takes the hands' coordinates and the joint-space chains' angles together (one
    operator, one product a frame), and one ``LabanEfforts`` their groups (each hand, each
    chain); what follows the fit is worked out in plain floats: a hand is 3 numbers, a chain a
    few angles, and numpy's cost per call is more than their arithmetic. So the windows hold
    the frames that had all of them: a frame before every arm and chain joint was seen (a
    robot's first frames) gives no Efforts, only the arms' shape where the hands are known."""

    def __init__(self, robot: Robot, config: FeaturesConfig, weights: np.ndarray) -> None:
        self.robot, name = robot, robot.name
        window = config.laban_window_s
        arms = robot.arms
        self.sides: tuple[str, ...] = arms.sides if arms is not None else ()
        self._hand_keys = [[keys.derived(name, f, s) for f in HANDS] for s in self.sides]
        self.elbow = elbow_frame(arms.joints) if arms is not None else None  # FK frame whose points to add
        self._pair = tuple(self.sides.index(s) for s in ("L", "R")) if set("LR") <= set(self.sides) else None
        self._both_keys = [keys.derived(name, f, BOTH_NAME) for f in BOTH]
        self.chains = joint_chains(robot, weights)
        self._joints = [i for members in self.chains.values() for i in members]
        self._joint_keys = [[keys.derived(name, f, c) for f in JOINT_SPACE] for c in self.chains]
        self._chain_weights = [weights[m].tolist() for m in self.chains.values()]
        # the fit's columns: each hand's x, y, z, then each chain's angles; a group each
        hands = 3 * len(self.sides)
        self._row = np.zeros(hands + len(self._joints))
        self._slices = [(3 * a, 3 * a + 3) for a in range(len(self.sides))]
        for members in self.chains.values():
            start = self._slices[-1][1] if self._slices else 0
            self._slices.append((start, start + len(members)))
        self._fit = PointDerivatives(len(self._row), config.fit_window_s, dim=1) if len(self._row) else None
        self._efforts = LabanEfforts(np.eye(len(self._slices)), window, [1e-3] * len(self.sides)
                                     + [JOINT_DISPLACEMENT] * len(self.chains))
        # motion segments: an arm chain's is its hand's path, another chain's its joints' path
        self._arm_of = {c: a for c, members in robot.chains.items() for a in range(len(self.sides))
                        if arms is not None and arms.joints[a][0] in members}
        self.segments = {c: SegmentRecorder(config.min_duration_s) for c in robot.chains}
        groups = robot.groups
        self._members = {c: list(groups[c]) for c in robot.chains}
        self._segment_keys = {c: {v: keys.derived(name, f, c) for v, f in SEGMENT_FEATURES.items()}
                              for c in robot.chains}

    @property
    def hand_velocity(self) -> np.ndarray:
        """The hands' velocities (arms, 3) from the last fit."""
        return self._fit.velocity[:3 * len(self.sides), 0].reshape(-1, 3) if self._fit else np.zeros((0, 3))

    def frame(self, t: float, positions: np.ndarray, points: np.ndarray | None, elbows: np.ndarray | None) -> Values:
        """This frame's descriptors from all joint ``positions``, the hand ``points`` (arms, 3;
        None where not known) and elbow points (FK frame ``elbow``; None without)."""
        out: Values = []
        if points is not None and self._pair is not None:
            rows = points.tolist()
            left, right = rows[self._pair[0]], rows[self._pair[1]]
            density = points_density(rows if elbows is None else rows + elbows.tolist())
            out += zip(self._both_keys, (math.dist(left, right), density, symmetry(left, right)), strict=True)
        fit = self._fit
        if fit is None or (points is None and self.sides):
            return out
        row, hands = self._row, 3 * len(self.sides)
        if hands:
            row[:hands] = points.reshape(-1)
        if self._joints:
            q = positions[self._joints]
            if not np.isfinite(q).all():
                return out
            row[hands:] = q
        if not fit.update(t, row):
            return out
        p, v, a, j = ([x[i:k] for i, k in self._slices] for x in fit.derivatives[..., 0].tolist())
        efforts = self._efforts.rows(fit.time, p, v, a, j)
        for names, e, vi, ai in zip(self._hand_keys, efforts, v, a, strict=False):  # (the hands first)
            _finite(out, names, (*e, 0.5 * (vi[0] * vi[0] + vi[1] * vi[1] + vi[2] * vi[2]), curvature(vi, ai)))
        for names, e, vc, w in zip(self._joint_keys, efforts[len(self.sides):], v[len(self.sides):],
                                   self._chain_weights, strict=True):
            _finite(out, names, (*e, 0.5 * sum(wi * x * x for wi, x in zip(w, vc, strict=True))))  # ½ Σ w_j q̇_j²
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
