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

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sonibus.bus import keys, messages

from . import catalog
from .config import FeaturesConfig
from .expressive import Expressive
from .filters import VelocityFilter
from .motion import OnsetDetector, weights
from .table import Robot

Message = dict[str, Any]
Range = tuple[np.ndarray, np.ndarray]

JUMP = 10.0  # a step faster than this × a joint's max velocity is a glitch, not motion: refused


@dataclass
class Output:
    """What one frame gave: the frame's derived values as ``names`` (below
    ``<robot>/derived/``) and ``values``, and events as ``(key, message)``; how many of the
    robot's joints the frame lacked or had as NaN; how many joint values the velocity filter
    refused (``rejected``, first of them ``refused``); how many derived values were pulled
    into their declared range (``clamped``) or were not finite and left out (``dropped``)."""

    t: float
    seq: int
    prefix: str  # <robot>/derived/
    names: list[str] = field(default_factory=list)
    values: list[Any] = field(default_factory=list)
    events: list[tuple[str, Message]] = field(default_factory=list)
    missing: int = 0
    nan: int = 0
    rejected: int = 0
    refused: str = ""
    clamped: int = 0
    dropped: int = 0

    @property
    def samples(self) -> list[tuple[str, Message]]:
        """Each value with the sample its own key carries: ``(key, {"t", "seq", "v"})``."""
        t, seq, prefix = self.t, self.seq, self.prefix
        return [(prefix + name, {"t": t, "seq": seq, "v": v}) for name, v in zip(self.names, self.values, strict=True)]

    def add(self, pairs: list[tuple[str, Any]]) -> None:
        """Add values given as ``(key, value)``."""
        cut = len(self.prefix)
        self.names += [key[cut:] for key, _ in pairs]
        self.values += [v for _, v in pairs]

    def bounded(self, values: list[float], low: list[float], high: list[float],
                publish: list[bool] | bool = True) -> tuple[list[float], list[bool] | None]:
        """``values`` clamped into ``[low, high]``, and which of them are finite (None: all);
        counts what is clamped or dropped among those to ``publish``."""
        for x, lo, hi in zip(values, low, high, strict=True):
            if not lo <= x <= hi:  # (NaN is not)
                break
        else:
            return values, None  # the usual: in range
        clamped, finite = [], []
        for x, lo, hi, counted in zip(values, low, high, [publish] * len(values) if publish.__class__ is bool
                                      else publish, strict=True):
            y = x if x != x else lo if x < lo else hi if x > hi else x
            clamped.append(y)
            finite.append(x - x == 0.0)
            if counted:
                if x - x != 0.0:
                    self.dropped += 1
                elif y != x:
                    self.clamped += 1
        return clamped, finite


class RobotFeatures:
    """``step(t, seq, values)`` per frame, ``values`` mapping joint keys to positions.

    Per frame everything is plain floats (numpy's cost per call on a robot's 17 values
    was most of a frame's); the numpy arrays of the robot's tables are turned into lists
    once, here."""

    def __init__(self, robot: Robot, config: FeaturesConfig, ranges: dict[str, Range] | None = None) -> None:
        """``ranges``: each derived key's declared range (``catalog.bounds``); what is
        published is clamped into it."""
        self.robot, self.config = robot, config
        self.frames = 0
        if ranges is None:
            ranges = catalog.bounds(catalog.derived(robot, config, {}))
        name, names = robot.name, robot.names
        self._prefix = keys.derived_frame(name) + "/"
        self._index = {keys.joint(name, j): i for i, j in enumerate(names)}
        self._positions = [math.nan] * len(names)  # the last finite position of each joint
        vmax = np.array([j.max_velocity or messages.MAX_VALUE for j in robot.joints])
        self._velocity = VelocityFilter(len(names), config.cutoff_hz, config.max_gap_s,
                                        np.minimum(JUMP * vmax, messages.MAX_VALUE))
        velocity_keys = [keys.derived(name, "velocity", j) for j in names]
        self._velocity_names = self._below(velocity_keys)
        self._velocity_range = _spans(ranges, velocity_keys, (-vmax, vmax))
        self._weights = weights([j.unit for j in robot.joints], names, config.weights)
        groups = robot.groups
        qom_keys = [keys.derived(name, "qom", g) for g in groups]
        self._groups = [(qom_name, g, members, [(j, w) for j in members if (w := float(self._weights[j]))])
                        for qom_name, (g, members) in zip(self._below(qom_keys), groups.items(), strict=True)]
        # (name, group, joints, weighted joints)
        self._qom_range = _spans(ranges, qom_keys, (0.0, messages.MAX_VALUE))
        self._detectors = {g: OnsetDetector(config.onset, config.offset, config.min_duration_s)
                           for g, i in groups.items() if g != "Body" and self._weights[i].sum() > 0}
        self._motion_key = keys.event(name, "motion")
        self._hands = robot.arms is not None and any(config.publishes(f) for f in ("hand", "hand_speed", "expressive"))
        if robot.arms is not None:
            sides = robot.arms.sides
            self._arm_joints = robot.arm_joints.tolist()  # type: ignore[union-attr]
            hand_keys = [keys.derived(name, "hand", s) for s in sides]
            speed_keys = [keys.derived(name, "hand_speed", s) for s in sides]
            self._hand_names, self._speed_names = self._below(hand_keys), self._below(speed_keys)
            unbounded = np.full((len(sides), 3), messages.MAX_VALUE)
            self._hand_range = _spans(ranges, hand_keys, (-unbounded, unbounded))
            self._speed_range = _spans(ranges, speed_keys, (0.0, messages.MAX_VALUE))
            self._hand_velocity = VelocityFilter(3 * len(sides), config.cutoff_hz, config.max_gap_s,
                                                 np.repeat(np.minimum(JUMP * np.array(self._speed_range[1]),
                                                                      messages.MAX_VALUE), 3))
        self._expressive = Expressive(robot, config, self._weights) if config.publishes("expressive") else None

    def _below(self, keys_: list[str]) -> list[str]:
        """The names of derived keys in a derived frame: below ``<robot>/derived/``."""
        return [key[len(self._prefix):] for key in keys_]

    def step(self, t: float, seq: int, values: Mapping[str, Any]) -> Output:
        """The features of the frame ``seq`` taken at ``t``."""
        out = Output(t, seq, self._prefix)
        self.frames += 1
        n, index = len(self._positions), self._index
        q = [math.nan] * n
        found = 0
        for key, value in values.items():
            i = index.get(key)
            if i is not None:
                found += 1
                if value.__class__ is float:
                    q[i] = value
                elif isinstance(value, int | float):
                    q[i] = float(value)
        out.missing = n - found
        out.nan = found - sum(1 for x in q if x - x == 0.0)
        fresh = self._velocity.step(t, q)
        refusals = self._velocity.refusals
        if refusals:
            out.rejected = len(refusals)
            out.refused = self.robot.names[refusals[0]]
            for i in refusals:
                q[i] = math.nan  # a glitch moves no hand
        self._positions = [x if x - x == 0.0 else p for x, p in zip(q, self._positions, strict=True)]
        v, usable = out.bounded(self._velocity.values, *self._velocity_range, fresh)
        if usable is not None:
            v = [x if ok else 0.0 for x, ok in zip(v, usable, strict=True)]
            fresh = [f and ok for f, ok in zip(fresh, usable, strict=True)]
        everywhere = all(fresh)
        if self.config.publishes("velocity"):
            if everywhere:
                out.names += self._velocity_names
                out.values += v
            else:
                out.names += [k for k, now in zip(self._velocity_names, fresh, strict=True) if now]
                out.values += [x for x, now in zip(v, fresh, strict=True) if now]
        hands, elbows = self._hand_features(t, out) if self._hands else (None, None)
        if self._expressive is not None:
            positions = np.array(self._positions)
            out.add(self._expressive.frame(t, positions, hands, elbows))
            self._expressive.record(t, positions, hands)
        moving = [abs(x) for x in v]
        updated = [everywhere or any(fresh[j] for j in members) for _, _, members, _ in self._groups]
        qoms = [sum([moving[j] * w for j, w in weighted], 0.0) for _, _, _, weighted in self._groups]
        qoms, usable = out.bounded(qoms, *self._qom_range, updated)
        if usable is not None:
            updated = [u and ok for u, ok in zip(updated, usable, strict=True)]
        for (qom_name, group, _, _), qom, now in zip(self._groups, qoms, updated, strict=True):
            if not now:
                continue
            if self.config.publishes("qom"):
                out.names.append(qom_name)
                out.values.append(qom)
            detector = self._detectors.get(group)
            change = detector.update(t, qom) if detector is not None else None
            if change is None:
                continue
            event = {"t": t, "kind": "motion", "chain": group, "state": change, "seq": seq}
            if self._expressive is not None:
                segment = self._expressive.segment(group, change, detector.crossed_at)
                if segment is not None:  # on the offset event, and as derived values
                    event["segment"] = segment
                    out.add(self._expressive.segment_samples(group, segment))
            if self.config.publishes("motion"):
                out.events.append((self._motion_key, event))
        return out

    def _hand_features(self, t: float, out: Output) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Publish the hands' features; their points (arms, 3) and, for the expressive
        descriptors, the elbows' (None where not known)."""
        arms = self.robot.arms
        assert arms is not None
        positions = self._positions
        angles = [[positions[j] for j in arm] for arm in self._arm_joints]
        if any(x != x for arm in angles for x in arm):
            return None, None  # an arm joint never seen yet
        elbow = None if self._expressive is None else self._expressive.elbow
        if elbow is None:
            points, elbows = arms.hand_points(angles), None
        else:  # (the expressive descriptors' points density takes the elbows too: one pass along the arms)
            at, elbows = arms.points_at(np.array(angles), (arms.axes.shape[1], elbow))
            points = at.ravel().tolist()
        hands, usable = out.bounded(points, *self._hand_range, self.config.publishes("hand"))
        if usable is not None and not all(usable):
            return None, None
        if self.config.publishes("hand"):
            out.names += self._hand_names
            out.values += [hands[i:i + 3] for i in range(0, len(hands), 3)]
        fresh = self._hand_velocity.step(t, points)
        if self.config.publishes("hand_speed") and all(fresh):
            hv = self._hand_velocity.values
            speeds, usable = out.bounded([math.sqrt(hv[i] * hv[i] + hv[i + 1] * hv[i + 1] + hv[i + 2] * hv[i + 2])
                                          for i in range(0, len(hv), 3)], *self._speed_range)
            for name, speed, good in zip(self._speed_names, speeds, usable or [True] * len(speeds), strict=True):
                if good:
                    out.names.append(name)
                    out.values.append(speed)
        return (np.array(points).reshape(-1, 3) if self._expressive is not None else None), elbows


def _spans(ranges: dict[str, Range], keys_: list[str], default: tuple[Any, Any]) -> tuple[list[float], list[float]]:
    """The declared ranges of ``keys_`` stacked and flattened to floats, ``(low, high)``;
    ``default`` (per key) where none is."""
    low = np.broadcast_to(np.asarray(default[0], dtype=float), (len(keys_), *np.shape(default[0])[1:]))
    high = np.broadcast_to(np.asarray(default[1], dtype=float), (len(keys_), *np.shape(default[1])[1:]))
    found = [ranges.get(key) for key in keys_]
    return (np.array([f[0] if f is not None else lo for f, lo in zip(found, low, strict=True)]).ravel().tolist(),
            np.array([f[1] if f is not None else hi for f, hi in zip(found, high, strict=True)]).ravel().tolist())
