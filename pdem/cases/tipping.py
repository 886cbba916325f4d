"""A cube tipping over the edge of the floor (tests/verification/test_common_plane_motion.py,
figure tipping.png).

Floor box x <= 0 (its edge is the line x = 0, z = 0 along y); unit cube of density rho placed
with its centroid e = 0.1 m beyond the edge, at rest, friction 60 deg, no damping,
``contact.point_area: 0.1``. It pivots about the floor edge.

Closed forms (rigid cube rotating by theta about the fixed edge, before lift-off): centroid
height ``z_c(theta) = a/2 cos(theta) - e sin(theta)`` (a = 1), pivot inertia
``I_p = m a^2 / 6 + m (e^2 + a^2/4)``, and by energy
``omega(theta) = sqrt(2 m g (z_c(0) - z_c(theta)) / I_p)``.
"""

from __future__ import annotations

import numpy as np

G = 9.81
RHO = 2000.0
KN = 1.0e9
E = 0.1  # centroid overhang beyond the floor edge


def tipping_scene(algorithm: str) -> str:
    """The floor and the overhanging cube, 1 s, no damping."""
    return f"""
name: tipping
gravity: [0, 0, {-G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 60.0}}}}
contact: {{algorithm: {algorithm}, point_area: 0.1}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [0, 2, 0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [{E - 0.5}, -0.5, 0], max: [{E + 0.5}, 0.5, 1]}}, material: rock}}
solve: {{time: 1.0, damping: none}}
"""


def pivot_inertia(m: float) -> float:
    """``I_p = m a^2 / 6 + m (e^2 + a^2/4)`` of the unit cube about the floor edge."""
    return m / 6.0 + m * (E * E + 0.25)


def centroid_height(theta):
    """``z_c(theta) = a/2 cos(theta) - e sin(theta)``."""
    return 0.5 * np.cos(theta) - E * np.sin(theta)


def angular_velocity(theta, m: float):
    """Rigid-pivot ``omega(theta) = sqrt(2 m g (z_c(0) - z_c(theta)) / I_p)``."""
    return np.sqrt(2.0 * m * G * (0.5 - centroid_height(theta)) / pivot_inertia(m))
