"""Derived movement features for sonification (adapter ``features``).

    [nodes.features]
    adapter = "features"
    robots = "pepper"

For each robot, from its joint frames: ``<robot>/derived/velocity/<Joint>``
(rad/s), ``<robot>/derived/hand/L|R`` ([x, y, z] m, Torso frame),
``<robot>/derived/hand_speed/L|R`` (m/s), ``<robot>/derived/qom/<Chain>|Body``
(rad/s), motion onsets and offsets on ``<robot>/events/motion``, and their
units and ranges on ``<robot>/info/derived``; opt-in, ``expressive``: Laban
Efforts, fluidity, kinetic energy, curvature, the arms' distance, density and
symmetry, joint-space Efforts where there is no kinematics, and per-segment
values on offsets (``expressive.py``). See docs/features.md.
"""

from .config import FEATURES, FeaturesConfig
from .processor import Features

__all__ = ["FEATURES", "Features", "FeaturesConfig"]
