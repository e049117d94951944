"""The features of a frame as computed before issue 35's per-frame work (5e09bd8): numpy
arrays for every step, a matrix product per joint for the hands. The straightforward
definition the plain-float path (``compute.RobotFeatures``) is checked against
(``test_reference.py``) and timed against (``bench/features.py``): kept as it was."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sonibus.adapters.features import catalog
from sonibus.adapters.features.config import FeaturesConfig
from sonibus.adapters.features.expressive import Expressive
from sonibus.adapters.features.filters import STILL
from sonibus.adapters.features.motion import OnsetDetector, weights
from sonibus.adapters.features.table import Robot
from sonibus.bus import keys, messages

Message = dict[str, Any]
Range = tuple[np.ndarray, np.ndarray]

JUMP = 10.0  # a step faster than this × a joint's max velocity is a glitch, not motion: refused


@dataclass
class ReferenceOutput:
    """What one frame gave: derived samples and events as ``(key, message)``; how many
    of the robot's joints the frame lacked or had as NaN; how many joint values the
    velocity filter refused (``rejected``, first of them ``refused``); how many derived
    values were pulled into their declared range (``clamped``) or were not finite and
    left out (``dropped``)."""

    samples: list[tuple[str, Message]] = field(default_factory=list)
    events: list[tuple[str, Message]] = field(default_factory=list)
    missing: int = 0
    nan: int = 0
    rejected: int = 0
    refused: str = ""
    clamped: int = 0
    dropped: int = 0

    def bounded(self, values: np.ndarray, span: Range, publish: np.ndarray | bool = True) -> tuple[np.ndarray,
                                                                                                    np.ndarray | None]:
        """``values`` clamped into ``span``, and which of them are finite (None: all); counts
        what is clamped or dropped among those to ``publish``."""
        low, high = span
        if (values >= low).all() and (values <= high).all():  # the usual: in range (NaN is not)
            return values, None
        finite = np.isfinite(values)
        clamped = np.clip(values, low, high)
        counted = np.broadcast_to(publish, values.shape)
        self.clamped += int(np.count_nonzero((clamped != values) & finite & counted))
        self.dropped += int(np.count_nonzero(~finite & counted))
        return clamped, finite


class ReferenceFeatures:
    """``step(t, seq, values)`` per frame, ``values`` mapping joint keys to positions."""

    def __init__(self, robot: Robot, config: FeaturesConfig, ranges: dict[str, Range] | None = None) -> None:
        """``ranges``: each derived key's declared range (``catalog.bounds``); what is
        published is clamped into it."""
        self.robot, self.config = robot, config
        self.frames = 0
        if ranges is None:
            ranges = catalog.bounds(catalog.derived(robot, config, {}))
        name, names = robot.name, robot.names
        self._index = {keys.joint(name, j): i for i, j in enumerate(names)}
        self._positions = np.full(len(names), np.nan)  # the last finite position of each joint
        vmax = np.array([j.max_velocity or messages.MAX_VALUE for j in robot.joints])
        self._velocity = ReferenceFilter(len(names), config.cutoff_hz, config.max_gap_s,
                                        np.minimum(JUMP * vmax, messages.MAX_VALUE))
        self._velocity_keys = [keys.derived(name, "velocity", j) for j in names]
        self._velocity_range = _spans(ranges, self._velocity_keys, (-vmax, vmax))
        self._weights = weights([j.unit for j in robot.joints], names, config.weights)
        groups = robot.groups
        self._groups = [(keys.derived(name, "qom", g), g) for g in groups]
        self._qom_range = _spans(ranges, [key for key, _ in self._groups], (0.0, messages.MAX_VALUE))
        self._members = np.zeros((len(groups), len(names)))  # group × joint: 1 if the joint is in the group
        for row, members in enumerate(groups.values()):
            self._members[row, members] = 1.0
        self._detectors = {g: OnsetDetector(config.onset, config.offset, config.min_duration_s)
                           for g, i in groups.items() if g != "Body" and self._weights[i].sum() > 0}
        self._motion_key = keys.event(name, "motion")
        self._hands = robot.arms is not None and any(config.publishes(f) for f in ("hand", "hand_speed", "expressive"))
        if robot.arms is not None:
            sides = robot.arms.sides
            self._hand_keys = [keys.derived(name, "hand", s) for s in sides]
            self._speed_keys = [keys.derived(name, "hand_speed", s) for s in sides]
            unbounded = np.full((len(sides), 3), messages.MAX_VALUE)
            self._hand_range = _spans(ranges, self._hand_keys, (-unbounded, unbounded))
            self._speed_range = _spans(ranges, self._speed_keys, (0.0, messages.MAX_VALUE))
            self._hand_velocity = ReferenceFilter(3 * len(sides), config.cutoff_hz, config.max_gap_s,
                                                 np.repeat(np.minimum(JUMP * self._speed_range[1],
                                                                      messages.MAX_VALUE), 3))
        self._expressive = Expressive(robot, config, self._weights) if config.publishes("expressive") else None

    def step(self, t: float, seq: int, values: Mapping[str, Any]) -> ReferenceOutput:
        """The features of the frame ``seq`` taken at ``t``."""
        out = ReferenceOutput()
        self.frames += 1
        q = np.full(len(self._index), np.nan)
        for key, value in values.items():
            i = self._index.get(key)
            if i is not None and isinstance(value, int | float):
                q[i] = value
        finite = np.isfinite(q)
        out.missing = len(q) - len(values.keys() & self._index.keys())
        out.nan = len(q) - out.missing - int(np.count_nonzero(finite))
        fresh = self._velocity.update(t, q)
        refused = self._velocity.refused
        if refused.any():
            out.rejected = int(np.count_nonzero(refused))
            out.refused = self.robot.names[int(np.argmax(refused))]
            finite &= ~refused  # a glitch moves no hand
        np.copyto(self._positions, q, where=finite)
        v, usable = out.bounded(self._velocity.velocity, self._velocity_range, fresh)
        if usable is not None:
            v = np.where(usable, v, 0.0)
            fresh &= usable
        if self.config.publishes("velocity"):
            out.samples += [(key, {"t": t, "seq": seq, "v": value})
                            for key, value, now in zip(self._velocity_keys, v.tolist(), fresh.tolist(), strict=True)
                            if now]
        hands, elbows = self._hand_features(t, seq, out) if self._hands else (None, None)
        if self._expressive is not None:
            out.samples += [(key, {"t": t, "seq": seq, "v": v})
                            for key, v in self._expressive.frame(t, self._positions, hands, elbows)]
            self._expressive.record(t, self._positions, hands)
        updated = self._members @ fresh > 0
        qoms, usable = out.bounded(self._members @ (np.abs(v) * self._weights), self._qom_range, updated)
        if usable is not None:
            updated &= usable
        for (key, group), qom, now in zip(self._groups, qoms.tolist(), updated.tolist(), strict=True):
            if not now:
                continue
            if self.config.publishes("qom"):
                out.samples.append((key, {"t": t, "seq": seq, "v": qom}))
            detector = self._detectors.get(group)
            change = detector.update(t, qom) if detector is not None else None
            if change is None:
                continue
            event = {"t": t, "kind": "motion", "chain": group, "state": change, "seq": seq}
            if self._expressive is not None:
                segment = self._expressive.segment(group, change, detector.crossed_at)
                if segment is not None:  # on the offset event, and as derived values
                    event["segment"] = segment
                    out.samples += [(key, {"t": t, "seq": seq, "v": v})
                                    for key, v in self._expressive.segment_samples(group, segment)]
            if self.config.publishes("motion"):
                out.events.append((self._motion_key, event))
        return out

    def _hand_features(self, t: float, seq: int, out: ReferenceOutput) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Publish the hands' features; their points (arms, 3) and, for the expressive
        descriptors, the elbows' (None where not known)."""
        assert self.robot.arms is not None and self.robot.arm_joints is not None
        angles = self._positions[self.robot.arm_joints]
        if not np.isfinite(angles).all():
            return None, None  # an arm joint never seen yet
        elbow = None if self._expressive is None else self._expressive.elbow
        if elbow is None:
            points, elbows = self.robot.arms.points(angles), None
        else:  # (the expressive descriptors' points density takes the elbows too: one pass along the arms)
            points, elbows = self.robot.arms.points_at(angles, (self.robot.arms.axes.shape[1], elbow))
        hands, usable = out.bounded(points, self._hand_range, self.config.publishes("hand"))
        if usable is not None and not usable.all():
            return None, None
        if self.config.publishes("hand"):
            out.samples += [(key, {"t": t, "seq": seq, "v": hand.tolist()})
                            for key, hand in zip(self._hand_keys, hands, strict=True)]
        fresh = self._hand_velocity.update(t, points.ravel())
        if self.config.publishes("hand_speed") and fresh.all():
            speeds, usable = out.bounded(np.linalg.norm(self._hand_velocity.velocity.reshape(hands.shape), axis=1),
                                         self._speed_range)
            ok = [True] * len(speeds) if usable is None else usable.tolist()
            out.samples += [(key, {"t": t, "seq": seq, "v": s})
                            for key, s, good in zip(self._speed_keys, speeds.tolist(), ok, strict=True) if good]
        return points, elbows


class ReferenceFilter:
    """``update(t, q)`` with ``n`` values at time ``t`` (s); ``velocity`` holds the estimates.

    ``max_rate`` (per signal, units/s; ``inf`` where unknown): a step implying a
    faster rate is refused. ``rejected`` counts the samples refused, ``refused``
    marks those of the last ``update``."""

    def __init__(self, n: int, cutoff_hz: float, max_gap_s: float = 0.5, max_rate: np.ndarray | None = None) -> None:
        if not cutoff_hz > 0 or not max_gap_s > 0:
            raise ValueError(f"cut-off ({cutoff_hz} Hz) and max gap ({max_gap_s} s) must be more than 0")
        self.cutoff_hz, self.max_gap_s = cutoff_hz, max_gap_s
        self.tau = 1.0 / (2.0 * math.pi * cutoff_hz)
        self.max_rate = np.full(n, np.inf) if max_rate is None else np.asarray(max_rate, dtype=float)
        if self.max_rate.shape != (n,) or not (self.max_rate > 0).all():
            raise ValueError(f"max_rate must be {n} values more than 0")
        self.velocity = np.zeros(n)
        self.known = np.zeros(n, dtype=bool)  # has a velocity (and a step to take the slope from)
        self.rejected = 0
        self._none = np.zeros(n, dtype=bool)
        self._none.flags.writeable = False
        self.refused = self._none
        self._last_q = np.full(n, np.nan)
        self._last_t = np.full(n, np.nan)
        self._last_r = np.zeros(n)
        self._last_dt = np.ones(n)

    def update(self, t: float, q: np.ndarray) -> np.ndarray:
        """Take the values ``q`` sampled at ``t``; returns which signals have a velocity for ``t``."""
        dt = t - self._last_t
        finite = np.isfinite(q)
        with np.errstate(invalid="ignore", over="ignore"):
            due = finite & (dt > 0) & (dt <= self.max_gap_s)
            step = due & (np.abs(q - self._last_q) <= self.max_rate * dt)
        refused = self._none
        if step.all():  # the usual frame: no boolean indexing, nothing refused
            self._step(slice(None), dt, q)
        else:
            with np.errstate(invalid="ignore"):
                refused = (due & ~step) | (finite & (dt < 0)) | np.isinf(q)  # a jump, time going back, inf
            if step.any():
                self._step(step, dt[step], q[step])
        spoiled = None
        if not math.isfinite(self.velocity.sum()):  # a rate beyond float, where max_rate is unknown
            spoiled = ~np.isfinite(self.velocity)
            step = step & ~spoiled
            refused = refused | spoiled
        if refused is not self._none or not step.all():
            start = (finite | refused) & ~step
            self.velocity[start] = 0.0
            self.known[start] = False
        np.copyto(self._last_q, q, where=finite)
        np.copyto(self._last_t, t, where=finite)
        if refused is not self._none and refused.any():
            gone = refused & (~finite if spoiled is None else ~finite | spoiled)  # nothing to start over from
            self._last_q[gone] = self._last_t[gone] = np.nan
            self.rejected += int(np.count_nonzero(refused))
        self.refused = refused
        return step

    def _step(self, step: np.ndarray | slice, dt: np.ndarray, q: np.ndarray) -> None:
        with np.errstate(over="ignore", invalid="ignore"):  # (what overflows is caught by update)
            r = (q - self._last_q[step]) / dt
            e = np.exp(-dt / self.tau)
            delta = dt / 2 - self.tau + dt * e / (1.0 - e)
            slope = np.where(self.known[step], (r - self._last_r[step]) / ((dt + self._last_dt[step]) / 2), 0.0)
            v = e * self.velocity[step] + (1.0 - e) * (r + slope * delta)
            v[np.abs(v) < STILL] = 0.0  # a decay to rest ends at rest, not at 1.9e-228 in a CSV
            self.velocity[step] = v
        self.known[step] = True
        self._last_r[step], self._last_dt[step] = r, dt

    def reset(self) -> None:
        """Forget everything: the next samples start over."""
        self.velocity[:] = 0.0
        self.known[:] = False
        self._last_q[:] = self._last_t[:] = np.nan


def _spans(ranges: dict[str, Range], keys_: list[str], default: tuple[Any, Any]) -> Range:
    """The declared ranges of ``keys_`` stacked, ``(low, high)``; ``default`` (per key) where none is."""
    low = np.broadcast_to(np.asarray(default[0], dtype=float), (len(keys_), *np.shape(default[0])[1:]))
    high = np.broadcast_to(np.asarray(default[1], dtype=float), (len(keys_), *np.shape(default[1])[1:]))
    found = [ranges.get(key) for key in keys_]
    return (np.array([f[0] if f is not None else lo for f, lo in zip(found, low, strict=True)]),
            np.array([f[1] if f is not None else hi for f, hi in zip(found, high, strict=True)]))
