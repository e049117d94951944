"""Simulated joints: each moves toward its target no faster than its speed limit.

This is how ALMotion's ``setAngles(names, angles, fractionMaxSpeed)`` behaves
as seen from the sensors: a move of 1 rad at speed 0.5 on a joint whose
maximum velocity is 4 rad/s takes 0.5 s.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from sonibus.bus.robot import RobotModel

STIFF = 0.1  # below this stiffness a joint's motor is off: it holds no target


class Body:
    """Positions, targets, per-joint speed limits and stiffness of one robot."""

    def __init__(self, model: RobotModel, pose: Mapping[str, float] | None = None) -> None:
        self.model = model
        self.names = model.joint_names
        self._index = {n: i for i, n in enumerate(self.names)}
        self._specs = model.joints
        # each joint's limits and top speed by index: ``set_targets`` clamps with them in line
        # (a ``JointSpec.clamp`` call per joint was most of the idle motion's frame, issue 35)
        self._low = [s.min for s in self._specs]
        self._high = [s.max for s in self._specs]
        self._top = [s.max_velocity for s in self._specs]
        pose = pose or {}
        self.positions = [s.clamp(pose.get(s.name, min(max(0.0, s.min), s.max))) for s in self._specs]
        self.targets = list(self.positions)
        self.velocity = [0.0] * len(self.names)
        self.stiffness = [1.0] * len(self.names)

    def set_targets(self, targets: Mapping[str, float], fraction: float) -> None:
        """Move ``targets`` (name → position) at ``fraction`` of each joint's max velocity."""
        speed = min(1.0, max(0.0, fraction))
        index, low, high, top, aims, velocity = (self._index, self._low, self._high, self._top,
                                                 self.targets, self.velocity)
        for name, value in targets.items():
            i = index[name]
            value = value if value > low[i] else low[i]  # JointSpec.clamp's min(max, max(min, value)),
            aims[i] = value if value < high[i] else high[i]  # without two calls per joint
            velocity[i] = top[i] * speed

    def set_stiffness(self, names: Iterable[str], value: float) -> None:
        for name in names:
            self.stiffness[self._index[name]] = value

    def halt(self) -> None:
        """Every joint holds where it is now."""
        self.targets = list(self.positions)

    def moving(self, names: Iterable[str] | None = None) -> bool:
        indexes = range(len(self.names)) if names is None else (self._index[n] for n in names)
        return any(self.positions[i] != self.targets[i] and self.stiffness[i] >= STIFF for i in indexes)

    def step(self, dt: float) -> None:
        """Advance ``dt`` seconds (nothing moves for ``dt <= 0``)."""
        if dt <= 0:
            return
        positions, stiffness, targets, velocity = self.positions, self.stiffness, self.targets, self.velocity
        for i, target in enumerate(targets):
            if target == positions[i]:  # (at rest, most joints: nothing to move)
                continue
            if stiffness[i] < STIFF:
                targets[i] = positions[i]
                continue
            error = target - positions[i]
            reach = velocity[i] * dt
            positions[i] = target if abs(error) <= reach else positions[i] + (reach if error > 0 else -reach)

    def pose(self) -> dict[str, float]:
        return dict(zip(self.names, self.positions, strict=True))
