"""One robot's features, frame by frame: joint velocities, hand positions and
speeds, quantity of motion per chain and for the body, motion onsets and
offsets. Every output carries the ``t`` and ``seq`` of its frame.

>>> from sonibus.bus.robot import load_model
>>> from sonibus.adapters.features import FeaturesConfig
>>> from sonibus.adapters.features.table import describe
>>> info = {"model": "pepper", "joints": [j.to_info() for j in load_model("pepper").joints]}
>>> features = RobotFeatures(describe("pepper", info), FeaturesConfig())
>>> frame = {f"pepper/joints/{j}": 0.0 for j in load_model("pepper").joint_names}
>>> features.step(0.00, 1, frame).samples            # a first frame: no velocity yet
[('pepper/derived/hand/L', {'t': 0.0, 'seq': 1, 'v': [0.297..., 0.164..., 0.114...]}), ('pepper/derived/hand/R', ...)]
>>> out = features.step(0.01, 2, {**frame, "pepper/joints/HeadYaw": 0.01})
>>> out.samples[0], len(out.samples)     # 1 rad/s from rest; 17 velocities, 2 hands, 2 speeds, 5 QoM
(('pepper/derived/velocity/HeadYaw', {'t': 0.01, 'seq': 2, 'v': 0.2695...}), 26)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sonibus.bus import keys

from .config import FeaturesConfig
from .filters import VelocityFilter
from .motion import OnsetDetector, weights
from .table import Robot

Message = dict[str, Any]


@dataclass
class Output:
    """What one frame gave: derived samples and events as ``(key, message)``, and
    how many of the robot's joints the frame lacked or had as NaN."""

    samples: list[tuple[str, Message]] = field(default_factory=list)
    events: list[tuple[str, Message]] = field(default_factory=list)
    missing: int = 0
    nan: int = 0


class RobotFeatures:
    """``step(t, seq, values)`` per frame, ``values`` mapping joint keys to positions."""

    def __init__(self, robot: Robot, config: FeaturesConfig) -> None:
        self.robot, self.config = robot, config
        self.frames = 0
        name, names = robot.name, robot.names
        self._index = {keys.joint(name, j): i for i, j in enumerate(names)}
        self._positions = np.full(len(names), np.nan)  # the last finite position of each joint
        self._velocity = VelocityFilter(len(names), config.cutoff_hz, config.max_gap_s)
        self._velocity_keys = [keys.derived(name, "velocity", j) for j in names]
        self._weights = weights([j.unit for j in robot.joints], names, config.weights)
        groups = robot.groups
        self._groups = [(keys.derived(name, "qom", g), g) for g in groups]
        self._members = np.zeros((len(groups), len(names)))  # group × joint: 1 if the joint is in the group
        for row, members in enumerate(groups.values()):
            self._members[row, members] = 1.0
        self._detectors = {g: OnsetDetector(config.onset, config.offset, config.min_duration_s)
                           for g, i in groups.items() if g != "Body" and self._weights[i].sum() > 0}
        self._motion_key = keys.event(name, "motion")
        self._hands = robot.arms is not None and (config.publishes("hand") or config.publishes("hand_speed"))
        if robot.arms is not None:
            sides = robot.arms.sides
            self._hand_keys = [keys.derived(name, "hand", s) for s in sides]
            self._speed_keys = [keys.derived(name, "hand_speed", s) for s in sides]
            self._hand_velocity = VelocityFilter(3 * len(sides), config.cutoff_hz, config.max_gap_s)

    def step(self, t: float, seq: int, values: Mapping[str, Any]) -> Output:
        """The features of the frame ``seq`` taken at ``t``."""
        out = Output()
        self.frames += 1
        q = np.full(len(self._index), np.nan)
        for key, value in values.items():
            i = self._index.get(key)
            if i is not None and isinstance(value, int | float):
                q[i] = value
        finite = np.isfinite(q)
        out.missing = len(q) - len(values.keys() & self._index.keys())
        out.nan = len(q) - out.missing - int(np.count_nonzero(finite))
        np.copyto(self._positions, q, where=finite)
        fresh = self._velocity.update(t, q)
        v = self._velocity.velocity
        if self.config.publishes("velocity"):
            out.samples += [(key, {"t": t, "seq": seq, "v": value})
                            for key, value, now in zip(self._velocity_keys, v.tolist(), fresh.tolist(), strict=True)
                            if now]
        if self._hands:
            self._hand_features(t, seq, out)
        qoms = (self._members @ (np.abs(v) * self._weights)).tolist()
        updated = (self._members @ fresh > 0).tolist()
        for (key, group), qom, now in zip(self._groups, qoms, updated, strict=True):
            if not now:
                continue
            if self.config.publishes("qom"):
                out.samples.append((key, {"t": t, "seq": seq, "v": qom}))
            detector = self._detectors.get(group)
            change = detector.update(t, qom) if detector is not None else None
            if change is not None and self.config.publishes("motion"):
                out.events.append((self._motion_key, {"t": t, "kind": "motion", "chain": group, "state": change,
                                                      "seq": seq}))
        return out

    def _hand_features(self, t: float, seq: int, out: Output) -> None:
        assert self.robot.arms is not None and self.robot.arm_joints is not None
        angles = self._positions[self.robot.arm_joints]
        if not np.isfinite(angles).all():
            return  # an arm joint never seen yet
        hands = self.robot.arms.points(angles)
        if self.config.publishes("hand"):
            out.samples += [(key, {"t": t, "seq": seq, "v": hand.tolist()})
                            for key, hand in zip(self._hand_keys, hands, strict=True)]
        fresh = self._hand_velocity.update(t, hands.ravel())
        if self.config.publishes("hand_speed") and fresh.all():
            speeds = np.linalg.norm(self._hand_velocity.velocity.reshape(hands.shape), axis=1)
            out.samples += [(key, {"t": t, "seq": seq, "v": float(s)})
                            for key, s in zip(self._speed_keys, speeds, strict=True)]
