"""A block on an incline (tests/verification/test_incline.py, figure incline.png).

The incline is represented by tilting gravity: ``g = |g| (sin psi, 0, -cos psi)`` acting on a
unit cube resting on a fixed horizontal base box, so the contact is face-to-face on z = 0 and
"down the slope" is +x. The slider's bottom is placed at the static overlap
``delta = m |g| cos psi / (kn A)``, so the normal contact starts in equilibrium.

Closed form (rigid block, Coulomb friction phi, no cohesion): when ``phi < psi`` the block
slides with constant acceleration ``a = |g| (sin psi - cos psi tan phi)``; when ``phi > psi``
it stays put.
"""

from __future__ import annotations

import math

from pdem.cases import vec

G = 9.81
RHO = 2000.0
KN = 1.0e9
PSI = 20.0  # incline angle, degrees


def incline_scene(phi: float, algorithm: str, end: str) -> str:
    """The base and the slider, friction ``phi`` (degrees); ``end`` is the solve limit, e.g.
    ``"time: 1.0"`` or ``"steps: 10000"``; no damping."""
    psi = math.radians(PSI)
    g = (G * math.sin(psi), 0.0, -G * math.cos(psi))
    delta = RHO * 1.0 * G * math.cos(psi) / KN  # m g cos(psi) / (kn A), A = 1 m^2, m = RHO
    return f"""
name: incline
gravity: {vec(g)}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: {phi}}}}}
contact: {{algorithm: {algorithm}}}
blocks:
  - {{name: base, box: {{min: [-5, -2, -1], max: [5, 2, 0]}}, material: rock, fixed: true}}
  - name: slider
    box: {{min: {vec((-0.5, -0.5, -delta))}, max: {vec((0.5, 0.5, 1.0 - delta))}}}
    material: rock
solve: {{{end}, damping: none}}
"""


def sliding_acceleration(phi: float) -> float:
    """``g (sin psi - cos psi tan phi)`` (negative when the block holds, phi > psi)."""
    psi, ph = math.radians(PSI), math.radians(phi)
    return G * (math.sin(psi) - math.cos(psi) * math.tan(ph))
