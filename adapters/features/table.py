"""The robot a processor works for, as its owner describes it on ``<robot>/info``:
the joint table, its chains, and the arms' kinematics (the chains its info carries,
else its model's) — or why there are none.

>>> from sonibus.bus.robot import load_model
>>> pepper = describe("pepper", {"model": "pepper", "joints": [j.to_info() for j in load_model("pepper").joints]})
>>> pepper.chains["RArm"][:2], pepper.arms is not None
(('RShoulderPitch', 'RShoulderRoll'), True)
>>> describe("bot", {"model": "robbie", "joints": [{"name": "A", "unit": "rad"}]}).unavailable
"no kinematics for model 'robbie'"
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .kinematics import Arms, from_info, load_arms


@dataclass(frozen=True)
class Joint:
    """One row of the joint table; what the owner did not give is None."""

    name: str
    unit: str = "rad"
    min: float | None = None
    max: float | None = None
    max_velocity: float | None = None
    chain: str = ""

    @property
    def velocity_unit(self) -> str:
        return {"rad": "rad/s", "fraction": "1/s"}.get(self.unit, f"{self.unit}/s")


@dataclass(frozen=True, eq=False)
class Robot:
    """A robot's joints (in the owner's order), chains, and arms (None, with the reason, if unknown)."""

    name: str
    model: str
    joints: tuple[Joint, ...]
    chains: dict[str, tuple[str, ...]]
    arms: Arms | None
    arm_joints: np.ndarray | None   # (arms, n): index in ``joints`` of each arm joint
    unavailable: str = ""

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def groups(self) -> dict[str, list[int]]:
        """Each chain's joints (as indexes in ``joints``), then ``Body``: all of them."""
        names = self.names
        return {**{c: [names.index(j) for j in members] for c, members in self.chains.items()},
                "Body": list(range(len(names)))}


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) \
        and math.isfinite(value) else None


def joints(info: dict[str, Any]) -> tuple[Joint, ...]:
    """The joint table of a ``<robot>/info``; ``ValueError`` if there is none."""
    table = info.get("joints")
    if not isinstance(table, list) or not table:
        raise ValueError("its info has no joint table")
    out = []
    for row in table:
        if not isinstance(row, dict) or not isinstance(row.get("name"), str) or not row["name"]:
            raise ValueError(f"joint table row {row!r} has no name")
        velocity = _number(row.get("max_velocity"))
        out.append(Joint(row["name"], str(row.get("unit") or "rad"), _number(row.get("min")), _number(row.get("max")),
                         velocity if velocity and velocity > 0 else None, str(row.get("chain") or "")))
    return tuple(out)


def describe(name: str, info: dict[str, Any]) -> Robot:
    """The robot ``name`` from its info; ``ValueError`` if the info has no usable joint table."""
    table = joints(info)
    model = str(info.get("model") or "")
    chains: dict[str, tuple[str, ...]] = {}
    for joint in table:
        if joint.chain:
            chains[joint.chain] = (*chains.get(joint.chain, ()), joint.name)
    index = {j.name: i for i, j in enumerate(table)}
    try:  # the chains the owner describes (a URDF robot's), else the model's own (Pepper, NAO)
        arms = from_info(info["kinematics"]) if "kinematics" in info else load_arms(model)
    except (KeyError, ValueError) as exc:
        return Robot(name, model, table, chains, None, None, str(exc.args[0]))
    missing = [j for arm in arms.joints for j in arm if j not in index]
    if missing:
        return Robot(name, model, table, chains, None, None, f"the joint table has no '{missing[0]}'")
    n = arms.axes.shape[1]  # a shorter chain's padding joints never move: any index will do
    arm_joints = np.array([[index[j] for j in arm] + [index[arm[0]]] * (n - len(arm)) for arm in arms.joints])
    return Robot(name, model, table, chains, arms, arm_joints)
