"""What a processor serves on ``<robot>/info/derived``: every derived key it
publishes, with its unit and range, so sinks can scale it, and what it cannot
compute and why.

Ranges are physical bounds: a joint velocity ±its maximum velocity; a hand
position the box its arm can reach (``box``; ``min``/``max`` is the cube around
it, one span for x, y and z); a hand speed the sum over the arm's joints of
maximum velocity × the length of the arm after the joint; a QoM the weighted
sum of its joints' maximum velocities.

>>> from sonibus.bus.robot import load_model
>>> from sonibus.adapters.features import FeaturesConfig
>>> from sonibus.adapters.features.table import describe as robot
>>> info = {"model": "pepper", "joints": [j.to_info() for j in load_model("pepper").joints]}
>>> entries = derived(robot("pepper", info), FeaturesConfig(), {"host": "h", "node": "features"})["derived"]
>>> [e for e in entries if e["name"] == "velocity/HeadYaw"][0]["max"]
7.33998
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from sonibus.bus import keys, messages

from .config import FeaturesConfig
from .descriptors import expressive_entries, segment_entries, segment_entry
from .kinematics import Arms
from .motion import weights
from .table import Robot


@cache
def _reach(arms: Arms, limits: tuple[tuple[tuple[float, float], ...], ...]) -> tuple[np.ndarray, np.ndarray]:
    return arms.reach_boxes(limits)


def _entry(robot: str, feature: str, name: str, unit: str, low: float | None, high: float | None,
           size: int = 1, **more: Any) -> dict[str, Any]:
    entry = {"name": f"{feature}/{name}", "key": keys.derived(robot, feature, name), "unit": unit, "size": size}
    if low is not None and high is not None:
        entry.update(min=round(float(low), 6), max=round(float(high), 6))
    return {**entry, **more}


def derived(robot: Robot, config: FeaturesConfig, processor: dict[str, str]) -> dict[str, Any]:
    """The ``<robot>/info/derived`` reply for ``robot``."""
    out: list[dict[str, Any]] = []
    name = robot.name
    if config.publishes("velocity"):
        out += [_entry(name, "velocity", j.name, j.velocity_unit, -j.max_velocity if j.max_velocity else None,
                       j.max_velocity) for j in robot.joints]
    out += _hands(robot, config)
    w = weights([j.unit for j in robot.joints], robot.names, config.weights)
    if config.publishes("expressive"):
        out += expressive_entries(robot, config, w, _hand_bounds(robot))
    known = all(j.max_velocity for j, weight in zip(robot.joints, w, strict=True) if weight)
    vmax = np.array([j.max_velocity or 0.0 for j in robot.joints])
    groups = robot.groups
    if config.publishes("qom"):
        out += [_entry(name, "qom", group, "rad/s", 0.0, float(w[i] @ vmax[i]) if known else None,
                       joints=[robot.names[k] for k in i if w[k]]) for group, i in groups.items()]
    chains = [c for c, i in groups.items() if c != "Body" and w[i].sum() > 0]
    if config.publishes("expressive"):
        out += segment_entries(robot, chains)
    reply: dict[str, Any] = {"robot": name, "derived": out, "processor": processor,
                             "filter": {"cutoff_hz": config.cutoff_hz, "max_gap_s": config.max_gap_s}}
    if config.publishes("motion"):
        reply["events"] = {"motion": {"key": keys.event(name, "motion"), "chains": chains}}
        if config.publishes("expressive"):
            reply["events"]["motion"]["segment"] = segment_entry(robot, chains)
    hands = [f for f in ("hand", "hand_speed") if config.publishes(f)]
    if robot.arms is None and hands:
        reply["unavailable"] = dict.fromkeys(hands, robot.unavailable)
    return reply


def bounds(reply: dict[str, Any]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each derived key of a ``derived`` reply with the range it declares, ``(low, high)``
    (a hand's: its box, per axis); ±the bus's physical bound where none is declared."""
    out = {}
    for entry in reply["derived"]:
        box = entry.get("box")
        low, high = (box["min"], box["max"]) if box else (entry.get("min", -messages.MAX_VALUE),
                                                         entry.get("max", messages.MAX_VALUE))
        out[entry["key"]] = (np.asarray(low, dtype=float), np.asarray(high, dtype=float))
    return out


def _hands(robot: Robot, config: FeaturesConfig) -> list[dict[str, Any]]:
    arms, index = robot.arms, robot.arm_joints
    if arms is None or index is None:
        return []
    joints = [[robot.joints[i] for i in arm[:len(names)]] for arm, names in zip(index, arms.joints, strict=True)]
    out = []
    if config.publishes("hand"):
        limits = tuple(tuple((j.min if j.min is not None else -np.pi, j.max if j.max is not None else np.pi)
                             for j in arm) for arm in joints)
        low, high = _reach(arms, limits)
        out += [_entry(robot.name, "hand", side, "m", low[a].min(), high[a].max(), 3, axes=["x", "y", "z"],
                       frame=arms.frame, box={"min": low[a].tolist(), "max": high[a].tolist()})
                for a, side in enumerate(arms.sides)]
    if config.publishes("hand_speed"):
        out += [_entry(robot.name, "hand_speed", side, "m/s", 0.0 if bound else None, bound)
                for side, bound in zip(arms.sides, _hand_bounds(robot), strict=True)]
    return out


def _hand_bounds(robot: Robot) -> list[float | None]:
    """Per arm, a bound on its hand's speed (m/s): Σ max velocity × lever arm; None if a joint's is unknown."""
    arms, index = robot.arms, robot.arm_joints
    if arms is None or index is None:
        return []
    levers = arms.lever_arms()
    out: list[float | None] = []
    for a, names in enumerate(arms.joints):
        joints = [robot.joints[i] for i in index[a][:len(names)]]
        bound = None
        if all(j.max_velocity for j in joints):
            arm_levers = levers[a][:len(joints)]  # (a shorter chain's padding moves nothing)
            bound = float(np.ceil(sum(j.max_velocity * r for j, r in zip(joints, arm_levers, strict=True)) * 10) / 10)
        out.append(bound)
    return out
