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

from collections.abc import Callable
from typing import Any

import numpy as np

from sonibus.bus import keys

from .config import FeaturesConfig
from .kinematic import PointDerivatives, geometry
from .laban import Efforts, LabanEfforts
from .segments import SEGMENT, SegmentRecorder
from .shape import kinetic_energy, points_density, symmetry
from .table import Robot

Emit = Callable[[str, float], None]  # (key, value) of this frame

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
    """The expressive descriptors of one robot; ``hands``, ``joints`` and ``record`` per frame."""

    def __init__(self, robot: Robot, config: FeaturesConfig, weights: np.ndarray) -> None:
        self.robot, name = robot, robot.name
        window, fit = config.laban_window_s, config.fit_window_s
        arms = robot.arms
        self.sides: tuple[str, ...] = arms.sides if arms is not None else ()
        self._fit = PointDerivatives(len(self.sides), fit) if self.sides else None
        self._efforts = LabanEfforts(np.eye(len(self.sides)), window)  # each hand its own group
        self._hand_keys = [[keys.derived(name, f, s) for f in HANDS] for s in self.sides]
        self._elbow = elbow_frame(arms.joints) if arms is not None else None
        self._pair = tuple(self.sides.index(s) for s in ("L", "R")) if set("LR") <= set(self.sides) else None
        self._both_keys = [keys.derived(name, f, BOTH_NAME) for f in BOTH]
        self.chains = joint_chains(robot, weights)
        self._joints = [i for members in self.chains.values() for i in members]
        self._joint_weights = weights[self._joints]
        self._joint_fit = PointDerivatives(len(self._joints), fit, dim=1) if self._joints else None
        # each chain one point of its angles, padded with zeros to the longest chain's length
        width = max((len(m) for m in self.chains.values()), default=0)
        self._pad = np.zeros((len(self.chains), width), dtype=int)  # where each padded coordinate is
        self._padded = np.zeros((len(self.chains), width), dtype=bool)
        start = 0
        for row, members in enumerate(self.chains.values()):
            self._pad[row, :len(members)] = np.arange(start, start + len(members))
            self._padded[row, len(members):] = True
            start += len(members)
        self._pad_weights = np.where(self._padded, 0.0, self._joint_weights[self._pad])
        self._joint_efforts = LabanEfforts(np.eye(len(self.chains)), window, JOINT_DISPLACEMENT)
        self._joint_keys = [[keys.derived(name, f, c) for f in JOINT_SPACE] for c in self.chains]
        # motion segments: an arm chain's is its hand's path, another chain's its joints' path
        self._arm_of = {c: a for c, members in robot.chains.items() for a in range(len(self.sides))
                        if arms is not None and arms.joints[a][0] in members}
        self.segments = {c: SegmentRecorder(config.min_duration_s) for c in robot.chains}
        groups = robot.groups
        self._members = {c: np.array(groups[c]) for c in robot.chains}
        self._segment_keys = {c: {v: keys.derived(name, f, c) for v, f in SEGMENT_FEATURES.items()}
                              for c in robot.chains}

    def hands(self, t: float, points: np.ndarray, q_arms: np.ndarray, emit: Emit) -> None:
        """The hands' descriptors from this frame's hand ``points`` (arms, 3) and arm angles."""
        if self._pair is not None:
            left, right = points[self._pair[0]], points[self._pair[1]]
            both = [points] if self._elbow is None else [points, self.robot.arms.points(q_arms, self._elbow)]
            for key, value in zip(self._both_keys, (float(np.linalg.norm(left - right)),
                                                    points_density(np.concatenate(both)), symmetry(left, right)),
                                  strict=True):
                emit(key, value)
        fit = self._fit
        if fit is None or not fit.update(t, points):
            return
        kappa = geometry(fit.velocity, fit.acceleration)[0]
        energy = kinetic_energy(fit.velocity)
        e = self._efforts.update(fit.time, fit.position, fit.velocity, fit.acceleration, fit.jerk)
        for i, names in enumerate(self._hand_keys):
            _emit_all(emit, names, (*_values(e, i), energy[i], kappa[i]))

    def joints(self, t: float, positions: np.ndarray, emit: Emit) -> None:
        """The joint-space descriptors of the chains with no kinematics from all joint ``positions``."""
        fit = self._joint_fit
        if fit is None:
            return
        q = positions[self._joints]
        if not np.isfinite(q).all() or not fit.update(t, q[:, None]):
            return
        p, v, a, j = (np.where(self._padded, 0.0, x[self._pad, 0])
                      for x in (fit.position, fit.velocity, fit.acceleration, fit.jerk))
        e = self._joint_efforts.update(fit.time, p, v, a, j)
        energy = 0.5 * np.einsum("ij,ij->i", self._pad_weights, v * v)
        for i, names in enumerate(self._joint_keys):  # ½ Σ w_j q̇_j²
            _emit_all(emit, names, (*_values(e, i), energy[i]))

    def record(self, t: float, positions: np.ndarray, hands: np.ndarray | None) -> None:
        """Add this frame to every chain's segment recorder (an arm chain's only with its hand)."""
        for chain, recorder in self.segments.items():
            arm = self._arm_of.get(chain)
            if arm is not None:
                if hands is not None:
                    recorder.add(t, hands[arm])
                continue
            q = positions[self._members[chain]]
            if np.isfinite(q).all():
                recorder.add(t, q)

    def segment(self, chain: str, state: str, at: float) -> dict[str, Any] | None:
        """Tell ``chain``'s recorder its motion changed at ``at``; the segment an offset closes."""
        recorder = self.segments.get(chain)
        return None if recorder is None else recorder.change(state, at)

    def segment_samples(self, chain: str, segment: dict[str, float]) -> list[tuple[str, float]]:
        """``segment``'s values as ``(key, value)`` of derived values ``segment_<value>/<chain>``."""
        names = self._segment_keys[chain]
        return [(names[v], value) for v, value in segment.items()]


def _values(e: Efforts, i: int) -> tuple[float, ...]:
    return tuple(float(x[i]) for x in (e.weight, e.time, e.flow, e.space, e.fluidity))  # type: ignore[index]


def _emit_all(emit: Emit, names: list[str], values: tuple[float, ...]) -> None:
    for key, value in zip(names, values, strict=True):
        if np.isfinite(value):  # Space with no displacement, κ below the speed floor: none
            emit(key, float(value))
