"""Undamped collapses for the energy budget (tests/verification/test_energy.py, issue 16):
the semicircular masonry arch, a pile of random polyhedra dropped into a box, a row of
toppling columns, a spinning block thrown at a wall, a row of soft zoned and rigid cubes
thrown at each other.

Closed forms: with ``damping: none`` the budget must balance, kinetic + joint spring energy +
energy dissipated in the joints = energy at the start + work of gravity (pdem.plugins.energy);
the limit-analysis critical thickness of a semicircular arch under its own weight is
t/R = 0.1075 (Heyman; thinner arches form a four-hinge mechanism and fall).
"""

from __future__ import annotations

import math

ARCH_CRITICAL_TR = 0.1075  # limit analysis, semicircular arch, self-weight only


def arch_scene(tr: float, *, radius: float = 5.0, n: int = 24, time: float = 2.0,
               damping: str = "none", friction: float = 60.0, extra: str = "") -> str:
    """Semicircle of mean radius ``radius`` in the x-z plane, ``n`` voussoirs (prisms 1 m deep)
    of thickness ``tr * radius`` on a fixed base box (the scene of issue 16)."""
    t = tr * radius
    ri, ro = radius - t / 2, radius + t / 2
    blocks = []
    for k in range(n):
        a0, a1 = k * math.pi / n, (k + 1) * math.pi / n
        base = [[ri * math.cos(a0), -0.5, ri * math.sin(a0)],
                [ro * math.cos(a0), -0.5, ro * math.sin(a0)],
                [ro * math.cos(a1), -0.5, ro * math.sin(a1)],
                [ri * math.cos(a1), -0.5, ri * math.sin(a1)]]
        blocks.append(f"  - {{name: v{k}, material: stone, prism: {{base: {base!r}, "
                      f"extrude: [0.0, 1.0, 0.0]}}}}")
    blocks.append(f"  - {{name: base, material: stone, fixed: true, box: {{min: [{-ro - 2!r}, "
                  f"-1.0, -1.0], max: [{ro + 2!r}, 1.0, 0.0]}}}}")
    return f"""name: arch-{tr}
gravity: [0.0, 0.0, -9.81]
materials: {{stone: {{density: 2000.0}}}}
joints: {{default: {{kn: 1.0e10, ks: 1.0e10, friction: {friction}}}}}
blocks:
{chr(10).join(blocks)}
solve: {{time: {time}, damping: {damping}}}
{extra}"""


def pile_scene(count: int = 40, time: float = 1.5, seed: int = 3) -> str:
    """``count`` random polyhedra dropped into a walled box, undamped."""
    return f"""name: dropped-pile
materials: {{rock: {{density: 2600.0}}}}
joints: {{default: {{kn: 1.0e8, ks: 5.0e7, friction: 30.0}}}}
blocks:
  - {{name: floor, box: {{min: [-2.5, -2.5, -0.5], max: [2.5, 2.5, 0.0]}}, material: rock, fixed: true}}
  - {{name: wall-x0, box: {{min: [-2.5, -2.5, 0.0], max: [-2.0, 2.5, 3.0]}}, material: rock, fixed: true}}
  - {{name: wall-x1, box: {{min: [2.0, -2.5, 0.0], max: [2.5, 2.5, 3.0]}}, material: rock, fixed: true}}
  - {{name: wall-y0, box: {{min: [-2.0, -2.5, 0.0], max: [2.0, -2.0, 3.0]}}, material: rock, fixed: true}}
  - {{name: wall-y1, box: {{min: [-2.0, 2.0, 0.0], max: [2.0, 2.5, 3.0]}}, material: rock, fixed: true}}
  - name: rock
    random: {{count: {count}, region: {{min: [-1.9, -1.9, 0.1], max: [1.9, 1.9, 2.5]}},
             size: [0.45, 0.6], vertices: 10, seed: {seed}}}
    material: rock
solve: {{time: {time}, damping: none}}
"""


def columns_scene(n: int = 6, time: float = 1.5) -> str:
    """A row of ``n`` slender columns (0.2 x 1 x 1.2 m, spaced 0.6 m) on a floor, the first
    tipped by an initial spin: dominoes, undamped."""
    blocks = [f"  - {{name: c{k}, material: rock, box: {{min: [{0.6 * k!r}, -0.5, 0.0], "
              f"max: [{0.6 * k + 0.2!r}, 0.5, 1.2]}}"
              + (", angular_velocity: [0.0, 2.5, 0.0]}" if k == 0 else "}") for k in range(n)]
    return f"""name: dominoes
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 5.0e9, ks: 5.0e9, friction: 35.0}}}}
blocks:
  - {{name: floor, box: {{min: [-1.0, -1.0, -0.5], max: [{0.6 * n + 2.0!r}, 1.0, 0.0]}},
     material: rock, fixed: true}}
{chr(10).join(blocks)}
solve: {{time: {time}, damping: none}}
"""


def ledge_scene(*, time: float = 2.0, floor: float = -3.0, action: str = "delete",
                gx: float = 3.0, pebble: float = 0.4) -> str:
    """A rock slides off a ledge (gravity tilted by ``gx`` m/s2 along x, 17 deg for 3; friction
    10 deg) and falls out of the model domain (bottom at ``floor``); a pebble (edge ``pebble``)
    slides on the ledge, staying in."""
    return f"""name: ledge
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 10.0}}}}
gravity: [{gx}, 0.0, -9.81]
blocks:
  - {{name: ledge, box: {{min: [-3, -1, -1], max: [0.5, 1, 0]}}, material: rock, fixed: true}}
  - {{name: rock, box: {{min: [-0.5, -0.5, 0.0], max: [0.5, 0.5, 1.0]}}, material: rock}}
  - {{name: pebble, box: {{min: [-2.5, {-pebble / 2}, 0.0], max: [{-2.5 + pebble}, {pebble / 2}, {pebble}]}},
     material: rock}}
solve: {{time: {time}, damping: none}}
domain: {{min: [-4, -2, {floor}], max: [4, 2, 3], action: {action}}}
"""


def thrown_block_scene(time: float = 0.4) -> str:
    """A cube spinning at 30 rad/s thrown at 5 m/s against a fixed wall, no gravity."""
    return f"""name: thrown
gravity: [0.0, 0.0, 0.0]
materials: {{rock: {{density: 2500.0}}}}
joints: {{default: {{kn: 1.0e9, ks: 1.0e9, friction: 30.0}}}}
blocks:
  - {{name: wall, box: {{min: [1.0, -2.0, -2.0], max: [1.5, 2.0, 2.0]}}, material: rock, fixed: true}}
  - {{name: cube, box: {{min: [-0.9, -0.25, -0.25], max: [-0.4, 0.25, 0.25]}}, material: rock,
     velocity: [5.0, 0.3, 0.0], angular_velocity: [3.0, 7.0, 30.0]}}
solve: {{time: {time}, damping: none}}
"""


# a row on a fixed floor: soft zoned cubes and rigid ones alternating, thrown at each other
# (tests/mpi/test_deformable_mpi.py's zoned row, every zoned cube elastic): z0 spins and hits
# r1, which turns and drifts 1.3 cm sideways, so when z2 catches r1 the row of z2's face
# gridpoints along one edge lies just outside r1's outline while most of their cells lie under
# r1's face, and r1's edge presses into z2's face there
ZONED_ROW = """
name: soft-row
materials:
  rock: {density: 2000}
  soft: {density: 2000, young: 5.0e7, poisson: 0.25}
joints: {default: {kn: 5.0e8, ks: 2.0e8, friction: 20.0}}
blocks:
  - {name: floor, box: {min: [-4, -1, -1], max: [4, 1, 0]}, material: rock, fixed: true}
  - {name: z0, box: {min: [-2.56, -0.5, 0], max: [-1.56, 0.5, 1]}, material: soft,
     zones: {size: 0.5}, velocity: [3, 0, 0], angular_velocity: [0, 0, 2]}
  - {name: r1, box: {min: [-1.53, -0.5, 0], max: [-0.53, 0.5, 1]}, material: rock,
     velocity: [-1, 0, 0]}
  - {name: z2, box: {min: [-0.48, -0.5, 0], max: [0.52, 0.5, 1]}, material: soft,
     zones: {size: 0.5}, velocity: [-2, 0, 0]}
solve: {steps: STEPS, damping: none}
"""


def zoned_row_scene(steps: int = 240) -> str:
    """The soft zoned row (above), undamped, for ``steps`` steps."""
    return ZONED_ROW.replace("STEPS", str(int(steps)))
