"""Instant descriptors of the arms' points: kinetic energy, contraction/expansion
(hand-to-hand distance, points density) and left/right symmetry; in the forms
of PyEyesWeb 1.1.1 (``KineticEnergy``, ``PointsDensity``, ``GeometricSymmetry``),
which the tests compare them with.

- kinetic energy E = ½ Σ α_i ‖v_i‖² (per unit mass: α_i = 1; m²/s²), Camurri,
  Lagerlöf & Volpe 2003; the joint-space proxy ½ Σ w_j q̇_j² (rad²/s²) where a
  chain has no kinematics
- points density D = (1/N) Σ ‖p_i − p̄‖ over hands and elbows (m), Glowinski
  et al. 2011: small when the arms gather toward their centre
- symmetry S = 1 − ‖p̃_L − M p̃_R‖ / (‖p̃_L‖ + ‖p̃_R‖ + ε), clipped at 0, with
  p̃ relative to the sagittal plane's origin (the Torso frame's) and M mirroring
  the lateral axis (y): 1 for mirrored hands, falling toward 0 as they part

>>> import numpy as np
>>> symmetry(np.array([0.2, 0.15, 0.1]), np.array([0.2, -0.15, 0.1]))
1.0
>>> round(points_density(np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])), 6)
0.1
"""

from __future__ import annotations

import math

import numpy as np

EPSILON = 1e-10  # PyEyesWeb's: a symmetry of two points at the origin is 1, not 0/0
LATERAL = 1      # the Torso frame's y axis (left) is the one a mirror turns over


def kinetic_energy(v: np.ndarray, alpha: np.ndarray | float = 1.0) -> np.ndarray:
    """½ α_i ‖v_i‖² per point, for velocities ``v`` of shape (n, dim)."""
    return 0.5 * np.asarray(alpha) * np.einsum("ij,ij->i", v, v)


def points_density(points: np.ndarray | list[list[float]]) -> float:
    """Mean distance of ``points`` (n, 3) from their barycentre (m)."""
    rows = points.tolist() if isinstance(points, np.ndarray) else points  # (a few points: floats beat numpy)
    n = len(rows)
    xs, ys, zs = zip(*rows, strict=True)
    cx, cy, cz = sum(xs) / n, sum(ys) / n, sum(zs) / n
    return sum(math.hypot(x - cx, y - cy, z - cz) for x, y, z in rows) / n


def symmetry(left: np.ndarray | list[float], right: np.ndarray | list[float], lateral: int = LATERAL) -> float:
    """Left/right symmetry of two points given relative to a point of the sagittal plane, in [0, 1]."""
    left, right = (x.tolist() if isinstance(x, np.ndarray) else x for x in (left, right))
    mirrored = list(right)
    mirrored[lateral] = -mirrored[lateral]
    error = math.dist(left, mirrored) / (math.hypot(*left) + math.hypot(*right) + EPSILON)
    return max(0.0, 1.0 - error)
