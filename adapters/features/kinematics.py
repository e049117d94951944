"""Forward kinematics of Pepper's and NAO's arms, with numpy, from ``arm_chain``
in ``robots.json`` (the robots' URDFs): metres in the Torso frame, x forward,
y left, z up.

A joint's frame is its parent's, moved by the joint's origin (translation, then
roll-pitch-yaw rotation) and turned by the joint angle about its axis; the hand
point is the origin of the ``LHand``/``RHand`` joint frame (the hand's opening
turns nothing). Both arms are stacked, so one call computes both hands.

>>> arms = load_arms("pepper")
>>> arms.hands({"RShoulderPitch": 1.5708}).round(3).tolist()   # right arm down, left arm forward
[[0.297, 0.165, 0.114], [-0.029, -0.165, -0.267]]
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from sonibus.bus.robot import reference

SIDES = ("L", "R")
EYE = np.eye(3)


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: Rz(yaw) · Ry(pitch) · Rx(roll)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


@dataclass(frozen=True, eq=False)
class Arms:
    """Arms of as many turning joints each (shoulder to wrist): per arm and joint the
    origin in the parent frame and the axis; the last origin is the hand point's."""

    sides: tuple[str, ...]
    joints: tuple[tuple[str, ...], ...]
    translations: np.ndarray  # (arms, n + 1, 3)
    rotations: np.ndarray     # (arms, n + 1, 3, 3)
    axes: np.ndarray          # (arms, n, 3), unit vectors

    def __post_init__(self) -> None:
        x, y, z = (self.axes[..., i] for i in range(3))
        zero = np.zeros_like(x)
        cross = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)], -2)
        object.__setattr__(self, "_cross", cross)  # Rodrigues: R = cos·I + sin·[a]× + (1 − cos)·a aᵀ
        object.__setattr__(self, "_outer", self.axes[..., :, None] * self.axes[..., None, :])

    def points(self, q: np.ndarray, upto: int | None = None) -> np.ndarray:
        """Positions ``(..., arms, 3)`` of frame ``upto`` of each arm (default: the hand;
        ``0`` is the first joint's) for angles ``q`` of shape ``(..., arms, n)``."""
        q = np.asarray(q, dtype=float)
        c, s = np.cos(q)[..., None, None], np.sin(q)[..., None, None]
        turns = c * EYE + s * self._cross + (1.0 - c) * self._outer  # type: ignore[attr-defined]
        offsets = turns @ self.translations[:, 1:, :, None]  # each joint's child origin, turned
        turns = turns @ self.rotations[:, 1:]
        position = self.translations[:, 0] + np.zeros((*q.shape[:-1], 3))
        rotation = self.rotations[:, 0]
        for i in range(self.axes.shape[1] if upto is None else upto):
            position = position + (rotation @ offsets[..., i, :, :])[..., 0]
            rotation = rotation @ turns[..., i, :, :]
        return position

    def hands(self, angles: Mapping[str, float]) -> np.ndarray:
        """Each arm's hand point ``(arms, 3)`` for joint angles by name (a joint not given is at 0)."""
        return self.points(np.array([[float(angles.get(j, 0.0)) for j in arm] for arm in self.joints]))

    def reach_boxes(self, limits: Sequence[Sequence[tuple[float, float]]], steps: int = 7,
                    margin_m: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
        """Per arm a box ``(low, high)``, each ``(arms, 3)``, holding every hand point: the hands over
        a grid of ``steps`` angles per joint between its limits (``limits[arm][joint]``), widened by
        ``margin_m`` and rounded outward to centimetres."""
        per_arm = []
        for arm_limits in limits:
            grids = np.meshgrid(*[np.linspace(low, high, steps) for low, high in arm_limits], indexing="ij")
            per_arm.append(np.stack([g.ravel() for g in grids], axis=-1))
        points = self.points(np.stack(per_arm, axis=1))
        low, high = points.min(axis=0) - margin_m, points.max(axis=0) + margin_m
        return np.floor(low * 100) / 100, np.ceil(high * 100) / 100

    def lever_arms(self) -> np.ndarray:
        """Per arm and joint ``(arms, n)``, a bound on the hand's distance from the joint's axis
        (the length of the chain after it): a joint turning at ω moves the hand at most ω times this."""
        lengths = np.linalg.norm(self.translations, axis=-1)
        return np.array([[arm[i + 1:].sum() for i in range(self.axes.shape[1])] for arm in lengths])


def _links(links: list[dict[str, Any]]) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]:
    turning = links[:-1]
    return (tuple(link["joint"] for link in turning),
            np.array([link["origin_xyz_m"] for link in links], dtype=float),
            np.array([rpy_matrix(*link["origin_rpy_rad"]) for link in links]),
            np.array([np.asarray(link["axis"], dtype=float) / np.linalg.norm(link["axis"]) for link in turning]))


def arm_chain(model: str) -> dict[str, list[dict[str, Any]]]:
    """``arm_chain`` of ``model`` in robots.json (``left``, ``right``: links from the
    shoulder to the hand); ``KeyError`` if sonibus has no kinematics for it."""
    try:
        return reference(model)["arm_chain"]
    except KeyError:
        raise KeyError(f"no kinematics for model '{model}'") from None


@cache
def load_arms(model: str) -> Arms:
    """Both arms of ``model``, left then right; ``KeyError`` if sonibus has no kinematics for it."""
    chain = arm_chain(model)
    left, right = _links(chain["left"]), _links(chain["right"])
    return Arms(SIDES, (left[0], right[0]), *(np.stack([a, b]) for a, b in zip(left[1:], right[1:], strict=True)))


def fk_vectors(model: str) -> dict[str, dict[str, Any]]:
    """The FK test vectors of ``model`` (computed from its URDF): name → ``{"q", "pos", "chain"}``."""
    return dict(reference(model)["fk_test_vectors_torso_frame_m"])
