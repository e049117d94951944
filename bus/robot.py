"""Robot models: joint tables, limits and postures (data in ``robots.json``).

>>> model = load_model("pepper")
>>> model.joint("HeadYaw").max
2.08567
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any


@dataclass(frozen=True)
class JointSpec:
    """One joint: its range in ``unit`` and its maximum velocity (unit/s)."""

    name: str
    min: float
    max: float
    max_velocity: float
    unit: str = "rad"
    chain: str = ""

    def clamp(self, value: float) -> float:
        return min(self.max, max(self.min, value))

    def to_info(self) -> dict[str, Any]:
        return {"name": self.name, "unit": self.unit, "min": self.min, "max": self.max,
                "max_velocity": self.max_velocity, "chain": self.chain}


@dataclass(frozen=True)
class RobotModel:
    """What a robot can move: an ordered joint table, chains and named postures."""

    name: str
    joints: tuple[JointSpec, ...]
    postures: dict[str, dict[str, float]] = field(default_factory=dict)
    description: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_name", {j.name: j for j in self.joints})

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def has_joint(self, name: str) -> bool:
        return name in self._by_name  # type: ignore[attr-defined]

    def joint(self, name: str) -> JointSpec:
        try:
            return self._by_name[name]  # type: ignore[attr-defined]
        except KeyError:
            raise KeyError(f"unknown joint '{name}' for {self.name} — known joints: "
                           f"{', '.join(self.joint_names)}") from None

    def chain(self, chain: str) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints if j.chain == chain)

    def posture(self, name: str) -> dict[str, float]:
        """A named posture, clamped to the joint limits."""
        return {j: self.joint(j).clamp(v) for j, v in self.postures[name].items()}


def models() -> tuple[str, ...]:
    """Names of the robot models sonibus ships."""
    return tuple(_reference())


@cache
def load_model(name: str) -> RobotModel:
    """The model called ``name`` (``pepper`` or ``nao``)."""
    return _build(name, reference(name))


def reference(name: str) -> dict[str, Any]:
    """The raw entry of model ``name`` in ``robots.json`` (``arm_chain``,
    ``fk_test_vectors_torso_frame_m``, sources...); ``KeyError`` for an unknown model."""
    table = _reference()
    if name not in table:
        raise KeyError(f"unknown robot model '{name}' — known models: {', '.join(table)}")
    return table[name]  # type: ignore[no-any-return]


@cache
def _reference() -> dict[str, Any]:
    text = resources.files(__package__).joinpath("robots.json").read_text(encoding="utf-8")
    return json.loads(text)


def _build(name: str, data: dict[str, Any]) -> RobotModel:
    chains = data["chains"]
    order = [j for chain in chains.values() for j in chain]
    joints = []
    for joint_name in order:
        raw = data["joints"][joint_name]
        chain = next(c for c, members in chains.items() if joint_name in members)
        unit = "rad" if raw["unit"] == "rad" else "fraction"
        joints.append(JointSpec(joint_name, float(raw["min"]), float(raw["max"]),
                                float(raw["max_velocity"]), unit, chain))
    postures = {k: {j: float(v) for j, v in p.items() if math.isfinite(float(v))}
                for k, p in data.get("postures_qibullet", {}).items() if isinstance(p, dict)}
    return RobotModel(name, tuple(joints), postures, data.get("model", ""))
