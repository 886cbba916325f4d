"""Scenes at the edges of the supported envelope (tests/extremes, docs/limits.md "The envelope").

Most cases are a box of sides ``(a, b, c)`` resting face-on on a fixed floor box larger than
it, so the contact is face-to-face with area ``A = a b`` and, under gravity ``g``, the static
overlap is ``delta = m g / (kn A) = rho c g / kn`` whatever the box's footprint.
"""

from __future__ import annotations

import math

from pdem.cases import vec

G = 9.81
RHO = 2000.0


def static_overlap(height: float, kn: float, g: float = G, rho: float = RHO) -> float:
    """``m g / (kn A) = rho c g / kn`` of a box of height ``c`` resting on its base."""
    return rho * height * g / kn


def box_on_floor(size=(1.0, 1.0, 1.0), *, kn=1.0e9, ks=None, friction=30.0, gravity=(0, 0, -G),
                 origin=(0.0, 0.0, 0.0), gap=None, velocity=(0.0, 0.0, 0.0), damping="none",
                 end="steps: 100", rho=RHO, extra_blocks="", contact="", name="box",
                 floor=None) -> str:
    """A box of ``size`` centred over ``origin`` on a fixed floor whose top face is at
    ``origin[2]``. ``gap``: the box's bottom height above the floor (negative: overlap);
    default: minus the static overlap under ``gravity``, so the box starts in equilibrium.
    ``floor``: the floor's (x, y) size (default: twice the box's, at least 2 m more)."""
    a, b, c = size
    ks = kn if ks is None else ks
    g = math.sqrt(sum(x * x for x in gravity))
    if gap is None:
        gap = -static_overlap(c, kn, abs(gravity[2]), rho) if g else 0.0
    ox, oy, oz = origin
    fa, fb = floor or (max(2.0 * a, a + 2.0), max(2.0 * b, b + 2.0))  # wider than the box
    return f"""
name: {name}
gravity: {vec(gravity)}
materials: {{rock: {{density: {rho}}}}}
joints: {{default: {{kn: {kn!r}, ks: {ks!r}, friction: {friction!r}}}}}
contact: {{{contact}}}
blocks:
  - name: floor
    box: {{min: {vec((ox - fa / 2, oy - fb / 2, oz - 1.0))}, max: {vec((ox + fa / 2, oy + fb / 2, oz))}}}
    material: rock
    fixed: true
  - name: {name}
    box:
      min: {vec((ox - a / 2, oy - b / 2, oz + gap))}
      max: {vec((ox + a / 2, oy + b / 2, oz + gap + c))}
    material: rock
    velocity: {vec(velocity)}
{extra_blocks}solve: {{{end}, damping: {damping}}}
"""


def incline_gravity(psi_deg: float, g: float = G) -> tuple[float, float, float]:
    """Gravity tilted by ``psi`` about y: the floor is an incline of angle psi, down-slope +x."""
    p = math.radians(psi_deg)
    return (g * math.sin(p), 0.0, -g * math.cos(p))


def sliding_acceleration(psi_deg: float, phi_deg: float, g: float = G) -> float:
    """``g (sin psi - cos psi tan phi)``: positive it slides, negative it holds."""
    p, f = math.radians(psi_deg), math.radians(phi_deg)
    return g * (math.sin(p) - math.cos(p) * math.tan(f))


def column_of_cubes(n: int, *, kn=1.0e9, side=1.0, end="steps: 1000", damping="local",
                    rho=RHO, preload=True) -> str:
    """``n`` cubes of side ``side`` stacked on a fixed floor; ``preload``: each joint at its
    static overlap (the joint under cube k carries the weight of the ``n - k`` cubes above it,
    itself included), else every cube just touching the one below."""
    w = rho * side**3 * G  # one cube's weight
    blocks = []
    z = 0.0
    for k in range(n):
        if preload:
            z -= (n - k) * w / (kn * side * side)  # this joint's static overlap
        blocks.append(f"  - {{name: c{k}, material: rock, box: {{min: {vec((-side / 2, -side / 2, z))}, "
                      f"max: {vec((side / 2, side / 2, z + side))}}}}}")
        z += side
    body = "\n".join(blocks)
    return f"""
name: column
gravity: [0.0, 0.0, {-G!r}]
materials: {{rock: {{density: {rho}}}}}
joints: {{default: {{kn: {kn!r}, ks: {kn!r}, friction: 30.0}}}}
blocks:
  - {{name: floor, material: rock, fixed: true, box: {{min: [-2.0, -2.0, -1.0], max: [2.0, 2.0, 0.0]}}}}
{body}
solve: {{{end}, damping: {damping}}}
"""


def thrown_at_plate(speed: float, thickness: float, *, kn=1.0e9, end="time: 0.03",
                    plate_fixed=True, bullet=(0.5, 0.5, 0.5), start_gap=0.1, extra="") -> str:
    """No gravity: a box ``bullet`` (its x, y, z sides) thrown along +x at ``speed`` at a plate
    of ``thickness`` (its near face at x = 0, 2 m x 2 m), starting ``start_gap`` away."""
    lx, ly, lz = bullet
    x0 = -start_gap - lx
    return f"""
name: impact
gravity: [0.0, 0.0, 0.0]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {kn!r}, ks: {kn!r}, friction: 30.0}}}}
blocks:
  - name: plate
    material: rock
    fixed: {str(plate_fixed).lower()}
    box: {{min: [0.0, -1.0, -1.0], max: [{thickness!r}, 1.0, 1.0]}}
  - name: bullet
    material: rock
    velocity: [{speed!r}, 0.0, 0.0]
    box: {{min: [{x0!r}, {-ly / 2!r}, {-lz / 2!r}], max: [{x0 + lx!r}, {ly / 2!r}, {lz / 2!r}]}}
{extra}solve: {{{end}, damping: none}}
"""
