"""Static solve: a stack of two unit cubes on a fixed floor relaxing to elastic equilibrium
(tests/verification/test_static.py, figure static.png).

The lower joint carries both weights and the upper one the top cube's, so the overlaps are
``delta_1 = 2 m g / (kn A)`` and ``delta_2 = m g / (kn A)``.
"""

from __future__ import annotations

RHO, KN, G = 2500.0, 1.0e9, 9.81

SCENE = f"""
gravity: [0, 0, -{G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - {{name: low, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
  - {{name: top, box: {{min: [-0.5, -0.5, 1], max: [0.5, 0.5, 2]}}, material: rock}}
solve: {{ratio: 1.0e-5, max_steps: 200000, damping: DAMP, mass_scaling: SCALE}}
"""


def stack_scene(damping: str, scaling: bool) -> str:
    """The two-cube stack, solved to ratio 1e-5 with ``damping`` and mass scaling on/off."""
    return SCENE.replace("DAMP", damping).replace("SCALE", str(scaling).lower())


def overlaps() -> tuple[float, float]:
    """Equilibrium overlaps (delta_1 of the lower joint, delta_2 of the upper one)."""
    m = RHO * 1.0
    return 2 * m * G / KN, m * G / KN
