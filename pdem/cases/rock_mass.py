"""Rock masses built the way a user builds them: blocks cut by joint sets (``cuts:``), joined
into concave blocks (``join:``) and excavated (``excavate:``) (tests/verification/
test_rock_mass.py, tests/mpi/test_rock_mass_mpi.py).

x = East, y = North, z = up; a plane of dip / dip direction has the upward normal
``n = (sin dip sin dd, sin dip cos dd, cos dip)`` (:func:`pdem.cases.dip_normal`).
"""

from __future__ import annotations

import math

import numpy as np

from pdem.cases import dip_normal, vec

G = 9.81
RHO = 2600.0


def _planes(normals, offsets) -> str:
    return f"{{normals: [{', '.join(vec(n) for n in normals)}], offsets: {vec(offsets)}}}"


def _box(lo, hi) -> str:
    return f"{{min: {vec(lo)}, max: {vec(hi)}}}"


# ---------------------------------------------------------------------------------------------
# 1. a Hoek-Bray wedge cut out of a slope by two joint sets

WEDGE_SETS = ((45.0, 5.0), (55.0, 135.0))  # (dip, dip direction) of sets JA and JB
WEDGE_KN = 1.0e9
WEDGE_H = 1.0  # slope crest height above the wedge's toe (the origin)


def wedge_line(sets=WEDGE_SETS) -> np.ndarray:
    """Unit vector along the line of intersection of the two sets, pointing down."""
    d = np.cross(dip_normal(*sets[0]), dip_normal(*sets[1]))
    d /= np.linalg.norm(d)
    return -d if d[2] > 0.0 else d


def slope_face(sets=WEDGE_SETS, dip: float = 65.0) -> np.ndarray:
    """Upward normal of the slope face: ``dip`` along the trend of the line of intersection."""
    d = wedge_line(sets)
    return dip_normal(dip, math.degrees(math.atan2(d[0], d[1])))


def wedge_planes(sets=WEDGE_SETS, h: float = WEDGE_H):
    """(normals, offsets) of the wedge: above both joints (through the origin), behind the
    slope face (through the origin), below the crest z = h."""
    na, nb = dip_normal(*sets[0]), dip_normal(*sets[1])
    return [-na, -nb, slope_face(sets), np.array([0.0, 0.0, 1.0])], [0.0, 0.0, 0.0, h]


def wedge_slope_scene(phi: float, *, sets=WEDGE_SETS, other_friction: float = 0.0,
                      time: float = 1.0, damping: str = "local") -> str:
    """A slope ``rock`` (x in [-3, 1], y in [-2, 1.5], z in [-1, H], behind the face through
    the origin) on a fixed ``base`` (z in [-1.5, -1]), cut by single planes of sets JA and JB
    through the origin (``range``: the slope only). The cuts make four pieces, in cut order
    ``rock[0]`` (below JA, below JB), ``rock[1]`` (below JA, above JB), ``rock[2]`` (above
    JA, below JB), ``rock[3]`` (above both: the wedge). The first three are joined to the
    fixed base (a joined block takes its first member's ``fixed``): only the wedge moves.

    Contacts across the faces of one set use that set's joint (friction ``phi``); any other
    contact the default joint, of friction ``other_friction``.
    """
    n_s = slope_face(sets)
    lo, hi = (-3.0, -2.0, -1.0), (1.0, 1.5, WEDGE_H)
    box_n = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    box_d = [hi[0], -lo[0], hi[1], -lo[1], hi[2], -lo[2]]
    joint = f"{{kn: {WEDGE_KN}, ks: {WEDGE_KN}, friction: {phi!r}}}"
    cuts = "\n".join(f"""  - {{name: J{k}, dip: {dip!r}, dip_direction: {dd!r}, origin: [0, 0, 0],
     joint: j{k}, range: {{box: {_box(lo, hi)}}}}}""" for k, (dip, dd) in zip("AB", sets, strict=True))
    return f"""
name: cut-wedge
gravity: [0, 0, {-G}]
materials: {{rock: {{density: {RHO}}}}}
joints:
  default: {{kn: {WEDGE_KN}, ks: {WEDGE_KN}, friction: {other_friction!r}}}
  jA: {joint}
  jB: {joint}
blocks:
  - name: rock
    planes: {_planes([n_s, *box_n], [0.0, *box_d])}
    material: rock
  - {{name: base, box: {_box((lo[0], lo[1], lo[2] - 0.5), (hi[0], hi[1], lo[2]))}, material: rock,
     fixed: true}}
cuts:
{cuts}
join: [[base, "rock[0]", "rock[1]", "rock[2]"]]
solve: {{time: {time!r}, damping: {damping}}}
"""


def wedge_displacement(sim) -> tuple[float, float]:
    """(displacement of the free wedge along the line of intersection, distance off it)."""
    b = sim.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    dx = b.x[i] - b.x0[i]
    d = wedge_line()
    along = float(dx @ d)
    return along, float(np.linalg.norm(dx - along * d))


# ---------------------------------------------------------------------------------------------
# 2. an L-shaped block joined from two boxes

L_A = ((0.0, 0.0, 0.0), (2.0, 1.0, 0.5))  # the long arm
L_B = ((0.0, 1.0, 0.0), (0.6, 2.5, 0.5))  # the short arm, on A's face y = 1
L_KN = 1.0e9


def l_block_scene(*, floor: bool, angular_velocity=(0.0, 0.0, 0.0), steps: int = 3000,
                  damping: str = "none", lift: float = 0.0) -> str:
    """Boxes ``a`` (``L_A``) and ``b`` (``L_B``) joined into an L lying flat (both bottoms at
    z = ``lift``); ``floor``: on a fixed floor under gravity, else in space (gravity 0)."""
    (a0, a1), (b0, b1) = L_A, L_B
    up = np.array([0.0, 0.0, lift])
    gravity = f"[0, 0, {-G}]" if floor else "[0, 0, 0]"
    floor_block = ("  - {name: floor, box: {min: [-1, -1, -0.5], max: [3, 3.5, 0]}, "
                   "material: rock, fixed: true}\n") if floor else ""
    return f"""
name: l-block
gravity: {gravity}
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {L_KN}, ks: {L_KN}, friction: 30.0}}}}
blocks:
  - {{name: a, box: {_box(np.add(a0, up), np.add(a1, up))}, material: rock,
     angular_velocity: {vec(angular_velocity)}}}
  - {{name: b, box: {_box(np.add(b0, up), np.add(b1, up))}, material: rock}}
{floor_block}join: [[a, b]]
solve: {{steps: {steps}, damping: {damping}}}
"""


def box_inertia(lo, hi, rho: float = RHO, about=None) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, centroid, inertia tensor about ``about`` (default: the centroid)) of a box."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    e = hi - lo
    m = rho * float(np.prod(e))
    c = 0.5 * (lo + hi)
    inertia = m / 12.0 * np.diag([e[1] ** 2 + e[2] ** 2, e[0] ** 2 + e[2] ** 2,
                                  e[0] ** 2 + e[1] ** 2])
    if about is not None:
        d = c - np.asarray(about, float)
        inertia = inertia + m * (d @ d * np.eye(3) - np.outer(d, d))  # parallel-axis theorem
    return m, c, inertia


def l_block_mass_properties(rho: float = RHO) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, centroid, inertia tensor about the centroid) of the L: the two boxes combined
    by the parallel-axis theorem."""
    ma, ca, _ = box_inertia(*L_A, rho)
    mb, cb, _ = box_inertia(*L_B, rho)
    m = ma + mb
    c = (ma * ca + mb * cb) / m
    return m, c, box_inertia(*L_A, rho, about=c)[2] + box_inertia(*L_B, rho, about=c)[2]


# ---------------------------------------------------------------------------------------------
# 3. a tunnel excavated at a model time in a jointed, confined rock box

TUNNEL_ROCK = ((-3.0, 0.0, 0.0), (4.0, 2.0, 6.0))  # 7 x 2 x 6 m, joints 1 m apart in x and z
TUNNEL_AXIS = (0.5, 2.5)  # (x, z) of the tunnel axis (along y): the middle of a 1 m cell
TUNNEL_RADIUS = 1.2
TUNNEL_SIDES = 16
TUNNEL_KN = 1.0e9


def tunnel_volume(radius: float = TUNNEL_RADIUS, sides: int = TUNNEL_SIDES,
                  length: float | None = None) -> float:
    """Volume of the polygonal cylinder inside the rock (corners on the circle)."""
    if length is None:
        length = TUNNEL_ROCK[1][1] - TUNNEL_ROCK[0][1]
    return radius ** 2 * sides * math.sin(2.0 * math.pi / sides) / 2.0 * length


def tunnel_scene(at: float, time: float, *, friction: float = 30.0) -> str:
    """The rock box ``TUNNEL_ROCK`` (group rock) cut by a vertical (dip 90, dd 90) and a
    horizontal (dip 0) joint set, 1 m apart, in a fixed frame (floor and two side walls,
    group frame); a 16-sided tunnel of radius 1.2 m along y through the whole box, excavated
    at model time ``at``; local damping, ``time`` s."""
    (x0, y0, z0), (x1, y1, z1) = TUNNEL_ROCK
    cx, cz = TUNNEL_AXIS
    frame = [("floor", (x0 - 1, y0, z0 - 1), (x1 + 1, y1, z0)),
             ("west", (x0 - 1, y0, z0), (x0, y1, z1)),
             ("east", (x1, y0, z0), (x1 + 1, y1, z1))]
    fixed = "\n".join(f"  - {{name: {n}, box: {_box(lo, hi)}, material: rock, group: frame, "
                      "fixed: true}" for n, lo, hi in frame)
    return f"""
name: tunnel
gravity: [0, 0, {-G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {TUNNEL_KN}, ks: {TUNNEL_KN}, friction: {friction!r}}}}}
blocks:
  - {{name: rock, box: {_box(*TUNNEL_ROCK)}, material: rock, group: rock}}
{fixed}
cuts:
  - {{name: vertical, dip: 90, dip_direction: 90, origin: [0, 0, 0], spacing: 1.0,
     groups: [rock]}}
  - {{name: horizontal, dip: 0, dip_direction: 0, origin: [0, 0, 0], spacing: 1.0,
     groups: [rock]}}
excavate:
  - cylinder: {{start: {vec((cx, y0 - 0.5, cz))}, end: {vec((cx, y1 + 0.5, cz))},
               radius: {TUNNEL_RADIUS}, sides: {TUNNEL_SIDES}}}
    time: {at!r}
solve: {{time: {time!r}, damping: local}}
"""


# ---------------------------------------------------------------------------------------------
# 4. an L block falling onto a cut stack (parallel determinism)

def l_on_stack_scene(time: float = 0.4, excavate_at: float = 0.15) -> str:
    """A 4 x 2 x 1 m stack (group stack) on a fixed floor, cut by a vertical joint set (1 m
    apart, joint ``vj``) and one horizontal plane at z = 0.5; its bottom-east cell is
    excavated at ``excavate_at``; an L joined from boxes ``a`` and ``b``, spinning, drops
    onto it across x = 0 (where a 2-rank split cuts the model)."""
    return f"""
name: l-on-stack
gravity: [0, 0, {-G}]
materials: {{rock: {{density: {RHO}}}}}
joints:
  default: {{kn: 1.0e8, ks: 1.0e8, friction: 30.0}}
  vj: {{kn: 1.0e8, ks: 1.0e8, friction: 20.0}}
blocks:
  - {{name: floor, box: {{min: [-3, -2, -0.5], max: [3, 2, 0]}}, material: rock, fixed: true}}
  - {{name: stack, box: {{min: [-2, -1, 0], max: [2, 1, 1]}}, material: rock, group: stack}}
  - {{name: a, box: {{min: [-0.9, -0.4, 1.2], max: [0.7, 0.4, 1.5]}}, material: rock,
     velocity: [0.3, 0.1, -0.5], angular_velocity: [0.4, 1.0, 0.3]}}
  - {{name: b, box: {{min: [-0.9, 0.4, 1.2], max: [-0.4, 1.2, 1.5]}}, material: rock}}
cuts:
  - {{name: V, dip: 90, dip_direction: 90, origin: [0, 0, 0], spacing: 1.0, joint: vj,
     groups: [stack]}}
  - {{name: H, dip: 0, dip_direction: 0, origin: [0, 0, 0.5], groups: [stack]}}
join: [[a, b]]
excavate:
  - {{box: {{min: [1.0, -1.5, 0.0], max: [2.5, 1.5, 0.5]}}, time: {excavate_at!r}}}
solve: {{time: {time!r}, damping: none}}
"""
