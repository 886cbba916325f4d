"""A 1 m block and a 1 cm pebble on one fixed base: partial mass scaling
(tests/verification/test_mass_scaling.py, bench/mass_scaling.py).

Mass ratio 1e6. Unscaled, eq. 87 pairs the pebble's mass with the big block's stiffness and
the whole scene steps at ~2e-7 s; ``solve.mass_scaling: {timestep: DT}`` with DT the big
block's own critical step scales the pebble alone (factor ~100) and the scene steps at DT.

Gravity can be tilted by ``psi`` (the incline of :mod:`pdem.cases.incline`: "down the slope"
is +x). Both blocks start on the base at their static overlap ``m g cos(psi) / (kn A)``; the
pebble may instead start ``lift`` above it (free fall) or pushed ``lift < 0`` further in (a
contact oscillation about the static overlap).

Closed forms (rigid blocks, Coulomb friction phi): an unscaled block slides at
``a = g (sin psi - cos psi tan phi)``; a block of scale factor s -- gravity and contact
forces act on its true mass, its inertia is s times larger -- slides at ``a / s``, falls at
``g / s``, and oscillates on its contact spring with the period ``2 pi sqrt(s m / (kn A))``
about the unchanged static overlap.
"""

from __future__ import annotations

import math

from pdem.cases import vec

G = 9.81
RHO = 2000.0
KN = 1.0e9
BIG, PEBBLE = 1.0, 0.01  # edge lengths (m)
PEBBLE_X = -4.0  # the pebble's centre, well away from the big block's path (+x)


def pebble_scene(end: str, *, psi: float = 0.0, phi: float = 10.0, scaling: str = "false",
                 lift: float = 0.0, pebble: bool = True, dt: float | None = None) -> str:
    """The base, the big block at the origin and (``pebble``) the pebble at x = PEBBLE_X;
    ``end`` the solve limit (``"time: 0.5"``), ``scaling`` the ``mass_scaling`` value
    (``"false"``, ``"{timestep: 1.0e-4}"``), ``dt`` a fixed step; no damping."""
    p = math.radians(psi)
    g = (G * math.sin(p), 0.0, -G * math.cos(p))
    gn = G * math.cos(p)
    d_big = RHO * BIG * gn / KN  # m g cos(psi) / (kn A) = rho a^3 g cos(psi) / (kn a^2)
    d_peb = RHO * PEBBLE * gn / KN - lift
    h = 0.5 * PEBBLE
    pebble_block = f"""
  - name: pebble
    box: {{min: {vec((PEBBLE_X - h, -h, -d_peb))}, max: {vec((PEBBLE_X + h, h, PEBBLE - d_peb))}}}
    material: rock""" if pebble else ""
    step = f", timestep: {{dt: {dt!r}}}" if dt is not None else ""
    return f"""
name: pebble
gravity: {vec(g)}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: {phi}}}}}
blocks:
  - {{name: base, box: {{min: [-6, -2, -1], max: [6, 2, 0]}}, material: rock, fixed: true}}
  - name: big
    box: {{min: {vec((-0.5, -0.5, -d_big))}, max: {vec((0.5, 0.5, BIG - d_big))}}}
    material: rock{pebble_block}
solve: {{{end}, damping: none, mass_scaling: {scaling}{step}}}
"""


def sliding_acceleration(psi: float, phi: float) -> float:
    """``g (sin psi - cos psi tan phi)`` of an unscaled block (degrees)."""
    p, f = math.radians(psi), math.radians(phi)
    return G * (math.sin(p) - math.cos(p) * math.tan(f))


def contact_period(edge: float, scale: float = 1.0) -> float:
    """``2 pi sqrt(s m / (kn A))`` of a cube of ``edge`` on its face (A = edge^2)."""
    return 2.0 * math.pi * math.sqrt(scale * RHO * edge / KN)


def static_overlap(edge: float, psi: float = 0.0) -> float:
    """``m g cos(psi) / (kn A)`` of a cube of ``edge`` resting on its face."""
    return RHO * edge * G * math.cos(math.radians(psi)) / KN
