"""Bus messages as Foxglove's messages (plain JSON, Foxglove's published schemas
in ``sonibus.schemas.foxglove``): events as ``foxglove.Log`` for the log panel,
frames as ``foxglove.FrameTransforms`` for the 3D panel. Pure functions: no bus,
no foxglove-sdk (the recorder uses them without it).

>>> log_message("pepper", {"t": 1.5, "kind": "behavior", "name": "animations/Hey_1", "state": "started"})
{'timestamp': {'sec': 1, 'nsec': 500000000}, 'level': 2, 'message': 'behavior animations/Hey_1 started', \
'name': 'pepper/behavior', 'file': '', 'line': 0}
>>> refused = {"t": 2.0, "kind": "command", "verb": "say", "args": {}, "ok": False, "error": "busy"}
>>> log_message("pepper", refused)["message"], log_message("pepper", refused)["level"]
('command say refused: busy', 3)

A joint's frame hangs from its parent's (the torso's for the shoulder): moved by
the joint's origin, turned by its origin's roll-pitch-yaw and then by the joint
angle about its axis, as ``adapters/features/kinematics.py`` computes it.

>>> arms = ArmFrames.of("pepper")
>>> first = arms.transforms("pepper", {"t": 3.0, "seq": 0, "names": ["LShoulderPitch"], "v": [0.0]})["transforms"][0]
>>> first["parent_frame_id"], first["child_frame_id"], first["translation"]
('pepper/Torso', 'pepper/LShoulderPitch', {'x': -0.057, 'y': 0.14974, 'z': 0.08682})
>>> first["rotation"]
{'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from sonibus.adapters.features.kinematics import arm_chain

LOG = "foxglove.Log"
FRAME_TRANSFORMS = "foxglove.FrameTransforms"
INFO, WARNING = 2, 3  # foxglove.LogLevel
WARNING_STATES = frozenset({"failed", "lost", "refused", "interrupted", "standby"})
ROOT = "Torso"  # the frame of robots.json's arm chains (x forward, y left, z up)

Quaternion = tuple[float, float, float, float]  # x, y, z, w


def timestamp(t: float) -> dict[str, int]:
    """A time in seconds since the epoch as Foxglove's ``{sec, nsec}``.

    >>> timestamp(1763900000.25)
    {'sec': 1763900000, 'nsec': 250000000}
    """
    sec = math.floor(t)
    nsec = round((t - sec) * 1e9)  # (t * 1e9 would lose the fraction's digits to the float's)
    if nsec == 1_000_000_000:
        sec, nsec = sec + 1, 0
    return {"sec": sec, "nsec": nsec}


def describe(event: Mapping[str, Any]) -> tuple[str, str]:
    """What an event says, as a readable line and its state (``refused`` for a
    command that was not ok)."""
    kind = event["kind"]
    if kind == "command":
        state = "ok" if event.get("ok") else "refused"
        error = f": {event['error']}" if event.get("error") else ""
        return f"command {event.get('verb', '?')} {state}{error}", state
    state = str(event.get("state", ""))
    subject = f'"{event.get("text", "")}"' if kind == "speech" else str(event.get("name") or event.get("chain") or "")
    if kind == "conflict" and isinstance(event.get("owner"), Mapping):
        owner = event["owner"]
        subject = f"owner {owner.get('node', '?')} on {owner.get('host', '?')}"
    return " ".join(part for part in (kind, subject, state) if part), state


def log_message(robot: str, event: Mapping[str, Any]) -> dict[str, Any]:
    """An event of ``robot`` as a ``foxglove.Log`` message: named ``<robot>/<kind>``,
    WARNING when something failed, was lost or refused, else INFO."""
    line, state = describe(event)
    return {"timestamp": timestamp(event["t"]), "level": WARNING if state in WARNING_STATES else INFO,
            "message": line, "name": f"{robot}/{event['kind']}", "file": "", "line": 0}


def rpy_quaternion(roll: float, pitch: float, yaw: float) -> Quaternion:
    """URDF's fixed-axis roll, pitch, yaw (Rz(yaw) · Ry(pitch) · Rx(roll)) as a quaternion.

    >>> [round(c, 4) for c in rpy_quaternion(0.0, 0.0, math.pi / 2)]
    [0.0, 0.0, 0.7071, 0.7071]
    """
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def axis_quaternion(axis: Sequence[float], angle: float) -> Quaternion:
    """A turn of ``angle`` radians about the unit vector ``axis``."""
    s = math.sin(angle / 2)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2))


def multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """The rotation ``a`` then, in its frame, ``b`` (Hamilton product ``a ⊗ b``)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


@dataclass(frozen=True)
class Link:
    """One joint of an arm chain: its parent joint (None: the root frame), its origin
    in the parent's frame, the axis it turns about (None: a point that does not turn
    with its value, the hand), and whether it slides along that axis instead (prismatic)."""

    joint: str
    parent: str | None
    xyz: tuple[float, float, float]
    rpy: Quaternion
    axis: tuple[float, float, float] | None
    slides: bool = False


@dataclass(frozen=True)
class ArmFrames:
    """The arm chains of a robot: its model's (``arm_chain`` in robots.json, from its URDF),
    or those its info carries (``kinematics``: a ROS robot's chains from its URDF)."""

    model: str
    links: tuple[Link, ...]
    root: str = ROOT

    @staticmethod
    @cache
    def of(model: str) -> ArmFrames:
        """The chains of ``model``; ``KeyError`` if sonibus has no kinematics for it."""
        chain = arm_chain(model)
        return ArmFrames(model, _links([chain["left"], chain["right"]]))

    @staticmethod
    def described(model: str, kinematics: Mapping[str, Any]) -> ArmFrames:
        """The chains of a robot info's ``kinematics``; ``ValueError`` if they are unusable."""
        try:
            return ArmFrames(model, _links(list(dict(kinematics["chains"]).values())), str(kinematics["root"]))
        except (KeyError, TypeError, ValueError, IndexError, ZeroDivisionError) as exc:
            raise ValueError(f"unusable kinematics: {type(exc).__name__}: {exc}") from None

    def transforms(self, robot: str, frame: Mapping[str, Any]) -> dict[str, Any]:
        """A frame as ``foxglove.FrameTransforms``: one transform per arm joint, parent
        frame to joint frame, named ``<robot>/<Joint>`` under ``<robot>/<root>``
        (a joint the frame does not hold is at 0)."""
        angles = dict(zip(frame["names"], frame["v"], strict=True))
        stamp = timestamp(frame["t"])
        out = []
        for link in self.links:
            rotation, (x, y, z) = link.rpy, link.xyz
            if link.axis is not None and link.slides:  # along the axis, in the frame the origin turned to
                x, y, z = (a + b for a, b in zip((x, y, z), rotate(link.rpy, tuple(  # type: ignore[assignment]
                    c * float(angles.get(link.joint, 0.0)) for c in link.axis)), strict=True))
            elif link.axis is not None:
                rotation = multiply(rotation, axis_quaternion(link.axis, float(angles.get(link.joint, 0.0))))
            qx, qy, qz, qw = rotation
            out.append({"timestamp": stamp, "parent_frame_id": f"{robot}/{link.parent or self.root}",
                        "child_frame_id": f"{robot}/{link.joint}", "translation": {"x": x, "y": y, "z": z},
                        "rotation": {"x": qx, "y": qy, "z": qz, "w": qw}})
        return {"transforms": out}


def rotate(q: Quaternion, v: Sequence[float]) -> tuple[float, float, float]:
    """Vector ``v`` turned by the unit quaternion ``q``."""
    x, y, z, _ = multiply(multiply(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return x, y, z


def _links(chains: Sequence[Sequence[Mapping[str, Any]]]) -> tuple[Link, ...]:
    """The links of every chain, each joint once (chains that share a start share its frames)."""
    links: dict[str, Link] = {}
    for chain in chains:
        parent = None
        for i, link in enumerate(chain):
            turns = i < len(chain) - 1  # the last (the hand) is a point: its value opens the hand
            axis = tuple(float(a) for a in link["axis"])
            norm = math.sqrt(sum(a * a for a in axis))
            links.setdefault(link["joint"], Link(
                link["joint"], parent, tuple(float(c) for c in link["origin_xyz_m"]),  # type: ignore[arg-type]
                rpy_quaternion(*link["origin_rpy_rad"]), tuple(a / norm for a in axis) if turns else None,  # type: ignore[arg-type]
                turns and link.get("type") == "prismatic"))
            parent = link["joint"]
    return tuple(links.values())


def arm_frames(info: Mapping[str, Any] | None) -> ArmFrames | None:
    """The arm chains of the robot ``info`` describes, or None (no info yet, or a
    model without kinematics)."""
    model = (info or {}).get("model")
    if not isinstance(model, str):
        return None
    try:
        if isinstance(info, Mapping) and "kinematics" in info:
            return ArmFrames.described(model, info["kinematics"])
        return ArmFrames.of(model)
    except (KeyError, ValueError):
        return None
