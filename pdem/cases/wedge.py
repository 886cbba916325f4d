"""The sliding rock wedge of the explicit 3D-DDA paper, Example 1 (tests/verification/
test_wedge.py, figure wedge.png; the geometry and the limit equilibrium are described in that
test module's docstring).

x = East, y = North, z = up. Joint A: dip 45 deg, dd 5 deg; joint B: dip 55 deg, dd 135 deg,
both through the origin; slope face dip 65 deg along the trend of the line of intersection;
the wedge is the tetrahedron ``nA.x >= 0, nB.x >= 0, nS.x <= 0, z <= H``.
"""

from __future__ import annotations

import math

import numpy as np

from pdem.cases import dip_normal, make_simulation, vec
from pdem.geometry.builders import from_planes

G = 9.81
RHO = 2600.0
KN = 1.0e9
H = 1.0

N_A = dip_normal(45.0, 5.0)
N_B = dip_normal(55.0, 135.0)


def intersection_line() -> np.ndarray:
    """Unit vector along the line of intersection of A and B, pointing down."""
    d = np.cross(N_A, N_B)
    d /= np.linalg.norm(d)
    return -d if d[2] > 0.0 else d


D = intersection_line()
N_S = dip_normal(65.0, math.degrees(math.atan2(D[0], D[1])))  # slope face
WEDGE_N = [-N_A, -N_B, N_S, np.array([0.0, 0.0, 1.0])]
WEDGE_D = [0.0, 0.0, 0.0, H]


def reactions(weight: np.ndarray) -> tuple[float, float]:
    """Normal reactions N_A, N_B of the two planes for sliding along D."""
    w_perp = weight - (weight @ D) * D
    c = float(N_A @ N_B)
    a, b = -float(w_perp @ N_A), -float(w_perp @ N_B)
    na = (a - c * b) / (1.0 - c * c)
    nb = (b - c * a) / (1.0 - c * c)
    return na, nb


def critical_friction() -> float:
    """Limit-equilibrium critical friction angle (degrees)."""
    w = np.array([0.0, 0.0, -1.0])
    na, nb = reactions(w)
    assert na > 0.0 and nb > 0.0  # sliding on both planes, not on one
    return math.degrees(math.atan(float(w @ D) / (na + nb)))


def sliding_acceleration(phi: float) -> float:
    """Rigid-wedge acceleration along D, ``a = (W.d - (N_A + N_B) tan(phi)) / m`` (negative:
    the wedge holds)."""
    na, nb = reactions(np.array([0.0, 0.0, -G]))  # per unit mass
    return float(np.array([0.0, 0.0, -G]) @ D) - (na + nb) * math.tan(math.radians(phi))


def wedge_scene(phi: float, algorithm: str = "fast") -> str:
    """Two fixed joint blocks and the wedge, pre-penetrated by the frictionless static
    overlaps ``N / (kn A_face)`` on each plane."""
    shape = from_planes(WEDGE_N, WEDGE_D)
    m = RHO * shape.volume
    na, nb = reactions(np.array([0.0, 0.0, -m * G]))

    def face_area(n):
        f = int(np.argmax(shape.normals @ n))
        assert shape.normals[f] @ n > 1.0 - 1e-9
        return shape.face_area(f)

    overlap = np.array([na / (KN * face_area(-N_A)), nb / (KN * face_area(-N_B))])
    shift = np.linalg.lstsq(np.array([N_A, N_B]), -overlap, rcond=None)[0]  # into both planes
    offsets = [d + float(n @ shift) for n, d in zip(WEDGE_N, WEDGE_D, strict=True)]
    box_n = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    box_d = [1.5, 3.0, 1.5, 2.0, 1.5, 1.5]  # x in [-3, 1.5], y in [-2, 1.5], z in [-1.5, 1.5]

    def planes(normals, offs) -> str:
        return (f"{{normals: [{', '.join(vec(n) for n in normals)}], "
                f"offsets: {vec(offs)}}}")

    return f"""
name: dda-wedge
gravity: [0, 0, {-G}]
materials: {{rock: {{density: {RHO}}}}}
joints: {{default: {{kn: {KN}, ks: {KN}, friction: {phi!r}}}}}
contact: {{algorithm: {algorithm}}}
blocks:
  - name: below_A
    planes: {planes([N_A, *box_n], [0.0, *box_d])}
    material: rock
    fixed: true
  - name: below_B
    planes: {planes([-N_A, N_B, *box_n], [0.0, 0.0, *box_d])}
    material: rock
    fixed: true
  - name: wedge
    planes: {planes(WEDGE_N, offsets)}
    material: rock
solve: {{time: 0.5, damping: none}}
"""


def wedge_simulation(phi: float, algorithm: str = "fast"):
    """A single-rank simulation of :func:`wedge_scene`."""
    return make_simulation(wedge_scene(phi, algorithm))


def displacement_history(sim, time: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Advance ``sim`` by ``time`` seconds; (times, displacement of the wedge along D)."""
    b = sim.blocks
    i = int(np.nonzero(b.fixed == 0)[0][0])
    n = int(round(time / sim.dt))
    t = np.empty(n)
    u = np.empty(n)
    for k in range(n):
        sim.advance()
        t[k] = sim.time
        u[k] = (b.x[i] - b.x0[i]) @ D
    return t, u
