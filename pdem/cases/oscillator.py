"""Translational dynamics of one block (tests/verification/test_oscillator.py, figures
oscillator.png and bounce.png).

A unit cube (side 1 m, density rho, so m = rho) rests face-on on a fixed floor box; the
contact area is A = 1 m^2 and the joint normal stiffness kn (Pa/m), so the contact is a
linear spring of stiffness kn A on the overlap un > 0 and nothing when open. No damping, or
Rayleigh damping (:func:`rayleigh`; the stiffness term a dashpot ``beta kn A`` at the closed
contact, tests/verification/test_joint_damping.py).
"""

from __future__ import annotations

import math

from pdem.cases import vec

G = 9.81
RHO = 2000.0
KN = 1.0e9


def cube_on_floor(z0: float, gravity=(0.0, 0.0, -G), velocity=(0.0, 0.0, 0.0), end="time: 1.0",
                  algorithm="fast", damping: str = "none") -> str:
    """The cube with its bottom face at height ``z0`` (negative: pre-penetrated);
    ``damping``: ``solve.damping`` (YAML flow)."""
    return f"""
name: oscillator
gravity: {vec(gravity)}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: 60.0}}}}
contact: {{algorithm: {algorithm}}}
blocks:
  - {{name: floor, box: {{min: [-2, -2, -1], max: [2, 2, 0]}}, material: rock, fixed: true}}
  - name: cube
    box: {{min: {vec((-0.5, -0.5, z0))}, max: {vec((0.5, 0.5, z0 + 1.0))}}}
    material: rock
    velocity: {vec(velocity)}
solve: {{{end}, damping: {damping}}}
"""


def rayleigh(fraction: float, frequency: float) -> str:
    """``solve.damping`` for Rayleigh damping (YAML flow)."""
    return f"{{mode: rayleigh, fraction: {fraction!r}, frequency: {frequency!r}}}"


def rayleigh_fraction(fraction: float, centre: float, frequency: float) -> float:
    """The fraction of critical damping Rayleigh damping set to ``fraction`` at ``centre``
    (Hz) gives a mode at ``frequency`` (Hz): ``(alpha / w + beta w) / 2``, ``alpha = fraction
    wc``, ``beta = fraction / wc``."""
    r = frequency / centre
    return 0.5 * fraction * (1.0 / r + r)


def free_fall_scene(g, v0) -> str:
    """One block in space (no contacts) under gravity ``g`` with initial velocity ``v0``,
    3000 steps: ``x(t) = x0 + v0 t + g t^2 / 2``."""
    return f"""
gravity: {vec(g)}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}}}}}
blocks:
  - {{name: stone, box: {{min: [0, 0, 10], max: [1, 2, 11]}}, material: rock, velocity: {vec(v0)}}}
solve: {{steps: 3000, damping: none}}
"""


def period(m: float = RHO, kn: float = KN) -> float:
    """Period ``T = 2 pi sqrt(m / (kn A))`` of the closed contact spring (A = 1 m^2)."""
    return 2.0 * math.pi * math.sqrt(m / kn)


def static_overlap(m: float = RHO, kn: float = KN) -> float:
    """Static overlap ``delta = m g / (kn A)`` of the cube resting on the floor."""
    return m * G / kn


def contact_duration(m: float = RHO, kn: float = KN) -> float:
    """Duration ``pi sqrt(m / (kn A))`` of one elastic impact (half a spring cycle)."""
    return math.pi * math.sqrt(m / kn)
