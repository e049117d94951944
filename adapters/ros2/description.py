"""A ROS robot as sonibus knows a robot, from its URDF: the joint table (``RobotModel``,
limits and velocities for validating commands and scaling values), the mimic joints
(filled into frames, never commanded), and the kinematic chains the user names,
which the robot's info carries for forward kinematics (``kinematics``: the
features processor's hand positions, Foxglove's 3D view).

A chain is the path of joints from the root link to the link the user names, fixed
joints folded into the next joint's origin, ending with a ``point`` (the named link's
origin). Continuous joints are revolute joints limited to [-π, π] (their positions
are wrapped there), prismatic joints are in metres.

>>> from .urdf import parse
>>> urdf = parse('''<robot name="arm"><link name="base"/><link name="l1"/><link name="tool"/>
...   <joint name="j1" type="continuous"><parent link="base"/><child link="l1"/></joint>
...   <joint name="flange" type="fixed"><parent link="l1"/><child link="tool"/><origin xyz="0.1 0 0"/></joint>
... </robot>''')
>>> robot = describe(urdf, {"arm": "tool"})
>>> robot.model.joint("j1").max, robot.model.joint("j1").chain
(3.141592653589793, 'arm')
>>> [(link["joint"], link["type"], link["origin_xyz_m"]) for link in robot.kinematics["chains"]["arm"]]
[('j1', 'revolute', [0.0, 0.0, 0.0]), ('tool', 'point', [0.1, 0.0, 0.0])]
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sonibus.bus import keys, messages
from sonibus.bus.robot import JointSpec, RobotModel

from .urdf import Joint, Mimic, Urdf, UrdfError

DEFAULT_VELOCITY = 1.0  # rad/s or m/s where a URDF gives none (continuous joints often do not)


@dataclass(frozen=True)
class Description:
    """What the adapter needs of a URDF."""

    model: RobotModel
    kinematics: dict[str, Any] | None
    mimics: dict[str, Mimic] = field(default_factory=dict)
    continuous: frozenset[str] = frozenset()

    def is_commanded(self, joint: str) -> bool:
        """Whether a controller takes this joint (a mimic joint follows its source instead)."""
        return joint not in self.mimics


def _matrix(xyz: tuple[float, ...], rpy: tuple[float, ...]) -> np.ndarray:
    roll, pitch, yaw = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    out = np.eye(4)
    out[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                   [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                   [-sp, cp * sr, cp * cr]]
    out[:3, 3] = xyz
    return out


def _origin(matrix: np.ndarray) -> tuple[list[float], list[float]]:
    """A transform back as URDF's xyz and fixed-axis roll, pitch, yaw."""
    r = matrix[:3, :3]
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    if math.hypot(r[0, 0], r[1, 0]) < 1e-12:  # pitch ±90°: roll and yaw turn about one axis; put it all in yaw
        roll, yaw = 0.0, math.atan2(-r[0, 1], r[1, 1])
    else:
        roll, yaw = math.atan2(r[2, 1], r[2, 2]), math.atan2(r[1, 0], r[0, 0])
    return [float(v) + 0.0 for v in matrix[:3, 3]], [roll + 0.0, pitch + 0.0, yaw + 0.0]  # (no -0.0)


def chain(urdf: Urdf, tip: str, root: str = "") -> list[dict[str, Any]]:
    """The kinematic chain to link ``tip``: each movable joint with its origin (fixed joints
    before it folded in) and axis, then the tip as a ``point``."""
    links: list[dict[str, Any]] = []
    pending = np.eye(4)  # fixed joints since the last movable one
    for joint in urdf.path(tip, root):
        pending = pending @ _matrix(joint.xyz, joint.rpy)
        if joint.movable:
            xyz, rpy = _origin(pending)
            links.append({"joint": joint.name, "type": "prismatic" if joint.type == "prismatic" else "revolute",
                          "origin_xyz_m": xyz, "origin_rpy_rad": rpy, "axis": list(joint.axis)})
            pending = np.eye(4)
    if not links:
        raise UrdfError(f"{urdf.source}: no movable joint between link '{root or urdf.root}' and link '{tip}'")
    xyz, rpy = _origin(pending)
    links.append({"joint": tip, "type": "point", "origin_xyz_m": xyz, "origin_rpy_rad": rpy, "axis": [1.0, 0.0, 0.0]})
    return links


def _spec(joint: Joint, chain_of: Mapping[str, str], default_velocity: float) -> JointSpec:
    low, high = (-math.pi, math.pi) if joint.type == "continuous" else (joint.lower, joint.upper)
    return JointSpec(joint.name, float(low or 0.0), float(high or 0.0), joint.velocity or default_velocity,
                     "m" if joint.type == "prismatic" else "rad", chain_of.get(joint.name, ""))


def describe(urdf: Urdf, chains: Mapping[str, str] | None = None, postures: Mapping[str, Mapping[str, float]] | None
             = None, root: str = "", default_velocity: float = DEFAULT_VELOCITY) -> Description:
    """The description of ``urdf`` with the chains ``{name: tip link}`` (from ``root``, default
    the URDF's root link) and named ``postures``; ``UrdfError`` if they do not fit it."""
    movable = urdf.movable
    if not movable:
        raise UrdfError(f"{urdf.source}: no movable joint (revolute, continuous or prismatic)")
    if len(movable) > messages.MAX_JOINTS:
        raise UrdfError(f"{urdf.source}: {len(movable)} movable joints; a frame carries at most "
                        f"{messages.MAX_JOINTS}")
    for joint in movable:
        if not joint.name or any(c in joint.name for c in keys.NOT_IN_NAMES):
            raise UrdfError(f"{urdf.source}: joint name '{joint.name}' cannot be a key chunk "
                            f"(it holds one of '{keys.NOT_IN_NAMES}')")
    paths = {name: chain(urdf, tip, root) for name, tip in (chains or {}).items()}
    chain_of: dict[str, str] = {}
    for name, links in paths.items():
        for link in links[:-1]:
            chain_of.setdefault(link["joint"], name)
    for joint in movable:  # a mimic joint moves with its source: it belongs to the same chain
        if joint.mimic is not None and joint.mimic.joint in chain_of:
            chain_of.setdefault(joint.name, chain_of[joint.mimic.joint])
    table = tuple(_spec(j, chain_of, default_velocity) for j in movable)
    model = RobotModel(urdf.name, table, {}, f"URDF robot '{urdf.name}' ({urdf.source})")
    mimics = {j.name: j.mimic for j in movable if j.mimic is not None}
    checked = {name: _posture(model, mimics, name, values) for name, values in (postures or {}).items()}
    model = RobotModel(urdf.name, table, checked, model.description)
    kinematics = {"root": root or urdf.root, "chains": paths} if paths else None
    return Description(model, kinematics, mimics, frozenset(j.name for j in movable if j.type == "continuous"))


def _posture(model: RobotModel, mimics: Mapping[str, Mimic], name: str, values: Mapping[str, Any]) -> dict[str, float]:
    out = {}
    for joint, value in values.items():
        if not model.has_joint(joint):
            raise UrdfError(f"posture '{name}': unknown joint '{joint}' — known joints: "
                            f"{', '.join(model.joint_names)}")
        if joint in mimics:
            raise UrdfError(f"posture '{name}': joint '{joint}' mimics '{mimics[joint].joint}'; set that one")
        spec = model.joint(joint)
        if not isinstance(value, int | float) or isinstance(value, bool) or not spec.min <= value <= spec.max:
            raise UrdfError(f"posture '{name}': {joint} = {value!r} is not within its limits "
                            f"[{spec.min:g}, {spec.max:g}]")
        out[joint] = float(value)
    if not out:
        raise UrdfError(f"posture '{name}' names no joint")
    return out


def wrap(angle: float) -> float:
    """A continuous joint's angle in [-π, π).

    >>> round(wrap(3 * math.pi / 2), 6)
    -1.570796
    """
    return (angle + math.pi) % (2 * math.pi) - math.pi
