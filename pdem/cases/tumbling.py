"""Torque-free rotation of an asymmetric rigid block, no gravity, no contacts
(tests/verification/test_tumbling.py, figure tumbling.png).

Closed form: the world angular momentum about the origin ``H = L + m x * v`` and the kinetic
energy ``K = 1/2 m |v|^2 + 1/2 w . L`` are constants of the motion.
"""

from __future__ import annotations

import numpy as np

from pdem.cases import vec


def random_polyhedron_vertices(seed: int = 7, n: int = 14) -> np.ndarray:
    """Points on an ellipsoid with semi-axes (0.6, 1.0, 1.5), off the origin: all on the hull,
    with no symmetry, so the principal axes are not the coordinate axes."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    return p * np.array([0.6, 1.0, 1.5]) + np.array([2.0, -1.0, 3.0])


# shape and initial angular velocity (world), chosen well off every principal axis
SHAPES = {
    "box123": ("box: {min: [0, 0, 0], max: [1, 2, 3]}", (2.0, 5.0, -7.0)),
    "random": ("polyhedron: {vertices: [" + ", ".join(vec(p) for p in random_polyhedron_vertices())
               + "]}", (5.0, -3.0, 4.0)),
}


def tumbling_scene(shape: str) -> str:
    """One block of ``SHAPES[shape]`` spinning in space, 5000 steps, no damping."""
    return f"""
gravity: [0, 0, 0]
materials: {{rock: {{density: 2500}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9}}}}
blocks:
  - name: tumbler
    {SHAPES[shape][0]}
    material: rock
    velocity: [0.3, -0.2, 0.5]
    angular_velocity: {vec(SHAPES[shape][1])}
solve: {{steps: 5000, damping: none}}
"""


def angular_momentum(blocks, row: int = 0) -> np.ndarray:
    """World angular momentum about the origin, ``L + m x * v``, of block ``row``."""
    m = float(blocks.mass[row])
    return blocks.L[row] + m * np.cross(blocks.x[row], blocks.v[row])


def kinetic_energy(blocks, row: int = 0) -> float:
    """``1/2 m |v|^2 + 1/2 w . L`` of block ``row``."""
    m = float(blocks.mass[row])
    return 0.5 * m * float(blocks.v[row] @ blocks.v[row]) + 0.5 * float(blocks.w[row] @ blocks.L[row])
