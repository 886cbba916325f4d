"""Staged scenes (pdem.stages): a slab on an incline for the strength-reduction factor of
safety (on a fixed base, or a rigid block on a zoned base), and a small stack for stage
changes and restarts.

The incline is tilted gravity as in :mod:`pdem.cases.incline`: ``g = |g| (sin psi, 0, -cos psi)``
on a slab resting on a fixed base. A thin slab keeps the normal stress under it nearly uniform
(the resultant's eccentricity ``h/2 tan psi`` is small against the slab's length), so the
joint fails all at once, as the closed form assumes:

    FS = (N tan(phi) + c A) / (W sin(psi)),  N = W cos(psi).

A cube would not: its resultant leaves the middle third at psi = 20 deg, the upslope corners
open, lose their cohesion, and the block fails progressively at a lower F (what 3DEC would
find too).
"""

from __future__ import annotations

import math

from pdem.cases import vec

G = 9.81
RHO = 2000.0
KN = 1.0e9
PSI = 20.0
SLAB = (2.0, 2.0, 0.1)  # length (down the slope), width, height


def slab_on_incline(joint: str) -> str:
    """The incline's tilted gravity, the fixed base and the slab resting on it at its static
    overlap ``m g cos(psi) / (kn A)`` (so that it starts at rest), joined by ``joint`` (the
    default joint's YAML mapping)."""
    psi = math.radians(PSI)
    g = (G * math.sin(psi), 0.0, -G * math.cos(psi))
    lx, ly, h = SLAB
    delta = RHO * h * G * math.cos(psi) / KN
    return f"""gravity: {vec(g)}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {joint}}}
blocks:
  - {{name: base, box: {{min: [-4, -3, -1], max: [4, 3, 0]}}, material: rock, fixed: true}}
  - name: slab
    box: {{min: {vec((-lx / 2, -ly / 2, -delta))}, max: {vec((lx / 2, ly / 2, h - delta))}}}
    material: rock
"""


def slab_fos_scene(phi: float, cohesion: float, *, tolerance: float = 0.005,
                   output: str | None = None) -> str:
    """Settle the slab (local damping), then search its factor of safety."""
    out = f"output: {{file: {output}}}\n" if output else ""
    joint = f"{{kn: {KN}, ks: {KN}, friction: {phi!r}, cohesion: {cohesion!r}}}"
    return f"""
name: slab-fos
{slab_on_incline(joint)}solve: {{damping: local}}
{out}stages:
  - {{name: settle, solve: {{ratio: 1.0e-6, max_steps: 20000}}}}
  - name: strength
    factor_of_safety: {{tolerance: {tolerance!r}, ratio: 1.0e-5, max_steps: 4000,
                        max_displacement: 0.02}}
"""


def slab_fos(phi: float, cohesion: float) -> float:
    """The closed form: ``(W cos(psi) tan(phi) + c A) / (W sin(psi))``."""
    psi, ph = math.radians(PSI), math.radians(phi)
    lx, ly, h = SLAB
    w = RHO * G * lx * ly * h
    return (w * math.cos(psi) * math.tan(ph) + cohesion * lx * ly) / (w * math.sin(psi))


ZONED_PHI = 30.0  # the friction of the joint the block slides on, on the zoned base


def zoned_fos_scene(output: str | None = None, checkpoint: str | None = None,
                    tolerance: float = 0.01) -> str:
    """A rigid block on a zoned Mohr-Coulomb base on the incline: settle (local damping), then
    the factor-of-safety search. The base sits on the fixed floor through a joint too strong
    to slide in the search's range (tan 60 / tan 20 = 4.8 > ``high``), the block on the base
    through the default joint (``ZONED_PHI``); the base's zones are weakened in the trials but
    strong enough to stay elastic (cohesion / 4 = 250 kPa against stresses of 20 kPa). The
    block sits off the base's centre (a cut of 2 ranks between them)."""
    psi = math.radians(PSI)
    g = (G * math.sin(psi), 0.0, -G * math.cos(psi))
    out = f"output: {{file: {output}}}\n" if output else ""
    ck = f"checkpoint: {{every_steps: 1000000, file: {checkpoint}}}\n" if checkpoint else ""
    return f"""
name: zoned-fos
gravity: {vec(g)}
materials:
  rock: {{density: {RHO}}}
  soft: {{density: {RHO}, young: 1.0e9, poisson: 0.25, model: mohr_coulomb, cohesion: 1.0e6,
          friction: 40, tension: 1.0e5}}
joints:
  default: {{kn: {KN}, ks: {KN}, friction: {ZONED_PHI}}}
  strong: {{kn: {KN}, ks: {KN}, friction: 60.0}}
joint_pairs: [{{groups: [floor, base], joint: strong}}]
blocks:
  - {{name: floor, box: {{min: [-3, -2, -1], max: [3, 2, 0]}}, material: rock, fixed: true,
     group: floor}}
  - {{name: base, box: {{min: [-2.5, -1.5, 0], max: [1.5, 1.5, 0.5]}}, material: soft,
     zones: {{size: 0.5}}, group: base}}
  - {{name: block, box: {{min: [0.2, -0.5, 0.5], max: [1.2, 0.5, 0.8]}}, material: rock,
     group: top}}
solve: {{damping: local}}
{out}{ck}stages:
  - {{name: settle, solve: {{ratio: 1.0e-6, max_steps: 30000}}}}
  - name: strength
    factor_of_safety: {{tolerance: {tolerance!r}, ratio: 1.0e-5, max_steps: 4000,
                        max_displacement: 0.02}}
"""


def zoned_fos() -> float:
    """The closed form of :func:`zoned_fos_scene`: ``tan(phi) / tan(psi)`` (a planar slide)."""
    return math.tan(math.radians(ZONED_PHI)) / math.tan(math.radians(PSI))


def stack_stages_scene(output: str, checkpoint: str | None = None) -> str:
    """Two cubes on a fixed floor and a third cube fixed beside them; stages: settle, then
    free the third and push it with a force while the first's joint gets weaker, then excavate
    the second (cut when built, removed when its stage starts)."""
    ck = f"checkpoint: {{every_steps: 100000, file: {checkpoint}}}\n" if checkpoint else ""
    return f"""
name: stack-stages
materials: {{rock: {{density: 2000.0}}}}
joints:
  default: {{kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
  weak: {{kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
joint_pairs: [{{groups: [floor, first], joint: weak}}]
blocks:
  - {{name: floor, box: {{min: [-3, -2, -0.5], max: [3, 2, 0]}}, material: rock, fixed: true,
     group: floor}}
  - {{name: first, box: {{min: [-1.5, -0.5, 0], max: [-0.5, 0.5, 1]}}, material: rock,
     group: first}}
  - {{name: second, box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1]}}, material: rock}}
  - {{name: third, box: {{min: [1.0, -0.5, 0], max: [2.0, 0.5, 1]}}, material: rock, fixed: true}}
solve: {{damping: local}}
output: {{file: {output}, every_steps: 100}}
{ck}stages:
  - {{name: settle, solve: {{steps: 300}}}}
  - name: load
    free: {{names: [third]}}
    force: [{{names: [third], force: [-2.0e4, 0, 0]}}]
    joints: {{weak: {{friction: 5.0}}}}
    solve: {{steps: 300}}
  - name: dig
    excavate: [{{box: {{min: [-0.5, -0.5, 0], max: [0.5, 0.5, 1.0]}}}}]
    velocity: [{{names: [first], velocity: [0, 0.1, 0]}}]
    solve: {{steps: 200, damping: none}}
"""
