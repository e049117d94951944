"""Forward kinematics of a robot's arms (kinematic chains), with numpy: Pepper's and
NAO's from ``arm_chain`` in ``robots.json`` (the robots' URDFs; metres in the Torso
frame, x forward, y left, z up), any other robot's from the ``kinematics`` its
owner's info carries (a ROS robot's chains from its URDF, ``adapters/ros2``).

A joint's frame is its parent's, moved by the joint's origin (translation, then
roll-pitch-yaw rotation) and then turned by the joint angle about its axis (a
prismatic joint slides along it instead); the hand point is the origin of the last
link of each chain (Pepper's ``LHand``/``RHand`` joint frame: the hand's opening
turns nothing). The chains are stacked, so one call computes every hand; a shorter
chain is padded with joints that have no axis and so never move.

>>> arms = load_arms("pepper")
>>> arms.hands({"RShoulderPitch": 1.5708}).round(3).tolist()   # right arm down, left arm forward
[[0.297, 0.165, 0.114], [-0.029, -0.165, -0.267]]
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache, cached_property
from math import cos, sin
from typing import Any

import numpy as np

from sonibus.bus.robot import reference

SIDES = ("L", "R")
EYE = np.eye(3)
GRID_POINTS = 20_000  # hand points computed per arm for its reach box


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's fixed-axis roll, pitch, yaw: Rz(yaw) · Ry(pitch) · Rx(roll)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


@dataclass(frozen=True, eq=False)
class Arms:
    """Arms (kinematic chains) of up to ``n`` joints each: per arm and joint the origin in
    the parent frame and the axis (zero: a padding joint); the last origin is the hand point's."""

    sides: tuple[str, ...]
    joints: tuple[tuple[str, ...], ...]
    translations: np.ndarray  # (arms, n + 1, 3)
    rotations: np.ndarray     # (arms, n + 1, 3, 3)
    axes: np.ndarray          # (arms, n, 3), unit vectors (zero for padding)
    sliding: np.ndarray | None = None  # (arms, n): 1.0 where the joint is prismatic (None: none is)
    frame: str = "Torso"      # the frame the chains start from
    guaranteed: bool = False  # reach boxes widened to hold every point, not only the grid's (see reach_boxes)

    def __post_init__(self) -> None:
        x, y, z = (self.axes[..., i] for i in range(3))
        zero = np.zeros_like(x)
        cross = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)], -2)
        sliding = np.zeros(self.axes.shape[:2]) if self.sliding is None else np.asarray(self.sliding, dtype=float)
        object.__setattr__(self, "sliding", sliding)
        object.__setattr__(self, "_cross", cross)  # Rodrigues: R = I + sin·[a]× + (1 − cos)·[a]×² (I for a = 0)
        object.__setattr__(self, "_square", cross @ cross)

    def points(self, q: np.ndarray, upto: int | None = None) -> np.ndarray:
        """Positions ``(..., arms, 3)`` of frame ``upto`` of each arm (default: the hand;
        ``0`` is the first joint's) for angles ``q`` of shape ``(..., arms, n)``."""
        return self.points_at(q, (self.axes.shape[1] if upto is None else upto,))[0]

    def points_at(self, q: np.ndarray, frames: tuple[int, ...]) -> list[np.ndarray]:
        """``points(q, upto)`` for each ``upto`` of ``frames``, in one pass along the arms."""
        n = max(frames)
        q = np.asarray(q, dtype=float)[..., :n]  # (the joints past frame upto move nothing before it)
        sliding = self.sliding[:, :n]  # type: ignore[index]
        angle = q * (1.0 - sliding)
        c, s = np.cos(angle)[..., None, None], np.sin(angle)[..., None, None]
        turns = EYE + s * self._cross[:, :n] + (1.0 - c) * self._square[:, :n]  # type: ignore[attr-defined]
        offsets = turns @ self.translations[:, 1:n + 1, :, None]  # each joint's child origin, turned
        if sliding.any():
            offsets = offsets + ((q * sliding)[..., None] * self.axes[:, :n])[..., None]  # slid along its axis
        turns = turns @ self.rotations[:, 1:n + 1]
        position = self.translations[:, 0] + np.zeros((*q.shape[:-1], 3))
        rotation = self.rotations[:, 0]
        found = {0: position}
        for i in range(n):
            position = position + (rotation @ offsets[..., i, :, :])[..., 0]
            found[i + 1] = position
            if i + 1 < n:
                rotation = rotation @ turns[..., i, :, :]
        return [found[f] for f in frames]

    def hand_points(self, angles: Sequence[Sequence[float]]) -> list[float]:
        """``points(angles).ravel()`` as floats, for one pose (``angles[arm][joint]``, ``n`` each):
        what a processor computes per frame. Nested from the hand inwards (Horner: each joint
        turns one vector, not a rotation matrix; turns about x, y or z touch two coordinates),
        in plain floats: ~4× fewer operations than the matrix products, and no numpy call
        (whose cost per call was most of ``points`` for one pose). Equal to ``points`` within
        rounding (1e-15 m)."""
        out: list[float] = []
        for (x0, y0, z0, base), steps, q in zip(self._plans, self._steps, angles, strict=True):
            px = py = pz = 0.0
            for j, kind, ax, ay, az, tx, ty, tz, rot in steps:
                if rot is None:  # u = t_(j+1) + rot_(j+1) · p: the child's origin, and the rest of the arm
                    ux, uy, uz = tx + px, ty + py, tz + pz
                else:
                    ux = tx + rot[0] * px + rot[1] * py + rot[2] * pz
                    uy = ty + rot[3] * px + rot[4] * py + rot[5] * pz
                    uz = tz + rot[6] * px + rot[7] * py + rot[8] * pz
                a = q[j]
                if kind == _X:  # p = turn_j · u (a sliding joint: u + q·axis)
                    c, s = cos(a), ax * sin(a)
                    px, py, pz = ux, c * uy - s * uz, s * uy + c * uz
                elif kind == _Y:
                    c, s = cos(a), ay * sin(a)
                    px, py, pz = c * ux + s * uz, uy, c * uz - s * ux
                elif kind == _Z:
                    c, s = cos(a), az * sin(a)
                    px, py, pz = c * ux - s * uy, s * ux + c * uy, uz
                elif kind == _ANY:  # Rodrigues: u cos + (k × u) sin + k (k · u)(1 − cos)
                    c, s = cos(a), sin(a)
                    d = (ax * ux + ay * uy + az * uz) * (1.0 - c)
                    px = ux * c + (ay * uz - az * uy) * s + ax * d
                    py = uy * c + (az * ux - ax * uz) * s + ay * d
                    pz = uz * c + (ax * uy - ay * ux) * s + az * d
                elif kind == _SLIDE:
                    px, py, pz = ux + a * ax, uy + a * ay, uz + a * az
                else:  # a padding joint
                    px, py, pz = ux, uy, uz
            if base is None:
                out += (x0 + px, y0 + py, z0 + pz)
            else:
                out += (x0 + base[0] * px + base[1] * py + base[2] * pz,
                        y0 + base[3] * px + base[4] * py + base[5] * pz,
                        z0 + base[6] * px + base[7] * py + base[8] * pz)
        return out

    @cached_property
    def _plans(self) -> list[tuple[float, float, float, tuple[float, ...] | None]]:
        """Per arm its first origin and rotation (None: none)."""
        return [(*self.translations[a, 0].tolist(), _turned(self.rotations[a, 0])) for a in range(len(self.sides))]

    @cached_property
    def _steps(self) -> list[list[tuple[Any, ...]]]:
        """Per arm, from the hand inwards, each joint's ``(joint, kind, axis..., child origin..., child
        rotation or None)``: what ``hand_points`` needs, as floats."""
        n = self.axes.shape[1]
        plans = []
        for a in range(len(self.sides)):
            steps = []
            for j in reversed(range(n)):
                axis = self.axes[a, j]
                principal = np.flatnonzero(axis)
                if self.sliding[a, j]:  # type: ignore[index]
                    kind = _SLIDE
                elif not axis.any():
                    kind = _NONE
                elif len(principal) == 1 and abs(axis[principal[0]]) == 1.0:
                    kind = (_X, _Y, _Z)[principal[0]]
                else:
                    kind = _ANY
                rot = None if j == n - 1 else _turned(self.rotations[a, j + 1])  # (the hand point's turns nothing)
                steps.append((j, kind, *axis.tolist(), *self.translations[a, j + 1].tolist(), rot))
            plans.append(steps)
        return plans

    def hands(self, angles: Mapping[str, float]) -> np.ndarray:
        """Each arm's hand point ``(arms, 3)`` for joint angles by name (a joint not given is at 0)."""
        n = self.axes.shape[1]
        return self.points(np.array([[float(angles.get(j, 0.0)) for j in arm] + [0.0] * (n - len(arm))
                                     for arm in self.joints]))

    def reach_boxes(self, limits: Sequence[Sequence[tuple[float, float]]], steps: int = 7,
                    margin_m: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
        """Per arm a box ``(low, high)``, each ``(arms, 3)``, holding every hand point: the hands over
        a grid of ``steps`` angles per joint between its limits (``limits[arm][joint]``; fewer steps
        when more than ``GRID_POINTS`` would be needed), widened by ``margin_m`` and rounded outward
        to centimetres. With ``guaranteed`` (chains from a robot's info: any URDF, however coarse
        its grid) each box is widened further by Σ lever × step / 2 over the arm's joints, a bound
        on how far any configuration's hand is from the nearest grid point's, so that features
        never clamp a real position into a box too small for it."""
        n = self.axes.shape[1]
        levers = self.lever_arms()
        low, high = np.zeros((len(limits), 3)), np.zeros((len(limits), 3))
        for a, arm_limits in enumerate(limits):
            moving = sum(1 for lo, hi in arm_limits if hi > lo)
            count = max(2, min(steps, int(GRID_POINTS ** (1 / max(moving, 1)))))
            axes = [np.linspace(lo, hi, count if hi > lo else 1) for lo, hi in arm_limits]
            grids = np.meshgrid(*axes, *([np.zeros(1)] * (n - len(arm_limits))), indexing="ij")
            q = np.zeros((grids[0].size, len(limits), n))
            q[:, a] = np.stack([g.ravel() for g in grids], axis=-1)
            points = self.points(q)[:, a]
            widen = margin_m
            if self.guaranteed:
                widen += sum(levers[a, i] * (hi - lo) / (2 * (count - 1)) for i, (lo, hi) in enumerate(arm_limits))
            low[a], high[a] = points.min(axis=0) - widen, points.max(axis=0) + widen
        return np.floor(low * 100) / 100, np.ceil(high * 100) / 100

    def lever_arms(self) -> np.ndarray:
        """Per arm and joint ``(arms, n)``, a bound on the hand's distance from the joint's axis
        (the length of the chain after it): a joint turning at ω moves the hand at most ω times this
        (a sliding joint moving at v moves it at v: 1)."""
        lengths = np.linalg.norm(self.translations, axis=-1)
        levers = np.array([[arm[i + 1:].sum() for i in range(self.axes.shape[1])] for arm in lengths])
        return np.where(self.sliding > 0, 1.0, levers)  # type: ignore[operator]


_X, _Y, _Z, _ANY, _SLIDE, _NONE = range(6)  # how a joint moves the hand point (hand_points)


def _turned(rotation: np.ndarray) -> tuple[float, ...] | None:
    """A rotation's 9 entries, row by row; None for none (the identity)."""
    return None if np.array_equal(rotation, EYE) else tuple(rotation.ravel().tolist())


def chains(sides: Sequence[str], links: Sequence[Sequence[Mapping[str, Any]]], frame: str = "Torso") -> Arms:
    """Arms from chains of links, each ``{"joint", "origin_xyz_m", "origin_rpy_rad", "axis", "type"?}``
    (``revolute``, ``prismatic``; the last link is the hand point whatever its type)."""
    n = max(len(chain) - 1 for chain in links)
    translations, rotations = np.zeros((len(links), n + 1, 3)), np.tile(EYE, (len(links), n + 1, 1, 1))
    axes, sliding = np.zeros((len(links), n, 3)), np.zeros((len(links), n))
    for a, chain in enumerate(links):
        moving, point = chain[:-1], chain[-1]
        for i, link in enumerate([*moving, point]):
            slot = i if i < len(moving) else n  # the hand point's origin goes last, after any padding
            translations[a, slot] = link["origin_xyz_m"]
            rotations[a, slot] = rpy_matrix(*link["origin_rpy_rad"])
        for i, link in enumerate(moving):
            axes[a, i] = np.asarray(link["axis"], dtype=float) / np.linalg.norm(link["axis"])
            sliding[a, i] = link.get("type") == "prismatic"
    return Arms(tuple(sides), tuple(tuple(link["joint"] for link in chain[:-1]) for chain in links),
                translations, rotations, axes, sliding, frame)


def from_info(kinematics: Mapping[str, Any]) -> Arms:
    """The arms of a robot info's ``kinematics`` (``{"root", "chains": {name: [link, ...]}}``);
    ``ValueError`` saying what is wrong."""
    try:
        named = dict(kinematics["chains"])
        if not named or any(len(chain) < 2 for chain in named.values()):
            raise ValueError("a chain needs a joint and its end point")
        arms = chains(tuple(named), list(named.values()), str(kinematics["root"]))
        object.__setattr__(arms, "guaranteed", True)
        return arms
    except (KeyError, TypeError, ValueError, ZeroDivisionError) as exc:
        raise ValueError(f"its info's kinematics are unusable: {type(exc).__name__}: {exc}") from None


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
    return chains(SIDES, [chain["left"], chain["right"]])


def fk_vectors(model: str) -> dict[str, dict[str, Any]]:
    """The FK test vectors of ``model`` (computed from its URDF): name → ``{"q", "pos", "chain"}``."""
    return dict(reference(model)["fk_test_vectors_torso_frame_m"])
