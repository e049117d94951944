"""Quantity of motion and motion onsets.

Quantity of motion (QoM) of a chain: the weighted sum of its joints' absolute
velocities, ``Σ w_j · |v_j|`` (rad/s). A joint measured in radians weighs 1, a
hand (an open fraction, not a rotation) 0; ``weights`` overrides by joint name.

A chain's motion state changes with hysteresis and a minimum duration: it
starts moving (``onset``) once its QoM has stayed at or above ``onset``
for ``min_duration_s``, and stops (``offset``) once it has stayed at or below
``offset`` (lower) for as long. Noise below ``onset`` never starts it, and a
gesture's brief pauses (under ``min_duration_s``) never stop it.

>>> d = OnsetDetector(onset=0.5, offset=0.2, min_duration_s=0.05)
>>> [d.update(t / 100, qom) for t, qom in enumerate([0.1, 0.9, 0.9, 0.9, 0.9, 0.9, 0.9])]
[None, None, None, None, None, None, 'onset']
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np


def weights(units: Sequence[str], names: Sequence[str], overrides: Mapping[str, float] | None = None) -> np.ndarray:
    """QoM weight of each joint: 1 for ``rad``, 0 otherwise, unless ``overrides`` names it."""
    overrides = overrides or {}
    return np.array([float(overrides.get(n, 1.0 if u == "rad" else 0.0)) for n, u in zip(names, units, strict=True)])


@dataclass
class OnsetDetector:
    """One chain's motion state from its QoM; ``update`` returns ``"onset"``, ``"offset"`` or None."""

    onset: float
    offset: float
    min_duration_s: float
    moving: bool = False
    _since: float | None = None  # when the QoM crossed toward the other state, while it stays there
    crossed_at: float = 0.0      # when the QoM crossed the threshold of the last change (before it was confirmed)

    def update(self, t: float, qom: float) -> str | None:
        crossed = qom <= self.offset if self.moving else qom >= self.onset
        if not crossed:
            self._since = None
            return None
        if self._since is None or t < self._since:
            self._since = t
        if t - self._since < self.min_duration_s - 1e-9:
            return None
        self.moving, self.crossed_at, self._since = not self.moving, self._since, None
        return "onset" if self.moving else "offset"
