"""A circular tunnel in elastic zoned rock under in-situ stress, plane strain, against the
closed form (docs/deformable.md, "Kirsch: a tunnel in elastic rock"):

A quarter of a thick ring (hole radius ``a`` = 1 m, outer polygon on radius ``R`` = 3 m, one
zone layer thick) is built as one zoned block, given the in-situ stress and the same stress
on its exposed faces (at rest), and the tunnel (a 32-sided polygonal cylinder) is excavated
by a stage: the zoned pieces the cut leaves meet at glued fictitious joints, as in 3DEC. The
symmetry planes and the two faces of the slice are on gridpoint rollers.

The closed form is Kirsch's problem on the finite ring (Brady & Brown's forms as ``R`` grows:
:func:`ring` tends to them, checked below): the uniform start stress with the hole's
traction removed and the outer traction held, in Michell's stress functions (the
axisymmetric Lame terms and the four ``cos 2 theta`` terms fitted to the two boundaries).

Tolerances, and what limits them: CST zones of the lattice at size 0.25 (boxes of 0.177 m in
the plane, two layers through the slice; ~5,400 zones), a polygonal hole and outer boundary,
and the glued joints' compliance (the crown, where the cut leaves a sliver piece, moves 7.4 %
(hydrostatic) of the scale more than the closed form; the springline 1.5 % less; softer joints
move both more). The wall's radial
displacement within 10 % of the hydrostatic scale ``p a / 2G`` at the springline and the
crown; the zones' radial and hoop stresses, averaged in bands along the axes between 1.5 a
and R, within 5 % of p. Near the wall (1-1.2 a) the hoop stress is 4-20 % of p short of the
closed form (not asserted: CST zones across a steep gradient).
"""

import math

import numpy as np
import pytest
from mpi4py import MPI

from pdem.config import parse_scene
from pdem.simulation import Simulation

E, NU, P = 1.0e9, 0.25, 1.0e6
G = E / (2 * (1 + NU))
A, R, H = 1.0, 3.0, 0.3  # hole radius, outer radius, slice thickness
SIZE = 0.25  # zone size: ~5,400 zones (at 0.3, ~4,600: the crown 12 % off, over the bound)


def ring(sx, sz, a, R, G, nu, r, th):
    """Plane strain ring ``a < r < R`` under the uniform start stress ``(sx, sz)``
    (tension positive, ``x`` and ``z`` the plane, ``th`` from +x towards +z) whose hole's
    traction is removed and outer traction held: the total stresses ``(srr, stt, srt)`` and
    the displacement since the start ``(ur, ut)``."""
    kap = 3 - 4 * nu
    m, d = 0.5 * (sx + sz), 0.5 * (sx - sz)
    # axisymmetric (phi = A0 r^2 + B0 ln r): srr = 2 A0 + B0 / r^2, -m at a, 0 at R
    b0 = -m / (1 / a**2 - 1 / R**2)
    a0 = -b0 / (2 * R**2)

    def rows(x):  # coefficients of srr / cos 2t and srt / sin 2t
        return [-2, 0, -6 / x**4, -4 / x**2], [2, 6 * x**2, -6 / x**4, -2 / x**2]

    c1, c2, c3, c4 = np.linalg.solve(np.array([*rows(a), *rows(R)]), [-d, d, 0.0, 0.0])
    cos2, sin2 = np.cos(2 * th), np.sin(2 * th)
    srr = m + d * cos2 + 2 * a0 + b0 / r**2 + (-2 * c1 - 6 * c3 / r**4 - 4 * c4 / r**2) * cos2
    stt = m - d * cos2 + 2 * a0 - b0 / r**2 + (2 * c1 + 12 * c2 * r**2 + 6 * c3 / r**4) * cos2
    srt = -d * sin2 + (2 * c1 + 6 * c2 * r**2 - 6 * c3 / r**4 - 2 * c4 / r**2) * sin2
    ur = (a0 * (kap - 1) * r - b0 / r + (-2 * c1 * r + (kap - 3) * c2 * r**3 + 2 * c3 / r**3
                                        + (kap + 1) * c4 / r) * cos2) / (2 * G)
    ut = (2 * c1 * r + (kap + 3) * c2 * r**3 + 2 * c3 / r**3 - (kap - 1) * c4 / r) * sin2 / (2 * G)
    return srr, stt, srt, ur, ut


def test_ring_tends_to_kirsch():
    """Brady & Brown (compression p vertical, K p horizontal): hoop p (3 - K) at the
    springline and p (3K - 1) at the crown, wall ``u_r = -(p a / 4G)((1 + K) -
    (1 - K)(3 - 4 nu) cos 2 theta)``."""
    for K in (1.0, 0.5):
        for th in (0.0, math.pi / 2):
            _, stt, _, ur, _ = ring(-K * P, -P, A, 1e5, G, NU, A, th)
            hoop = (3 - K) * P if th == 0.0 else (3 * K - 1) * P
            assert -stt == pytest.approx(hoop, rel=1e-6)
            u = -(P * A / (4 * G)) * ((1 + K) - (1 - K) * (3 - 4 * NU) * math.cos(2 * th))
            assert ur == pytest.approx(u, rel=1e-6)


def scene(K: float, sides: int = 16) -> str:
    arc = [(R * math.cos(math.pi / 2 * i / sides), R * math.sin(math.pi / 2 * i / sides))
           for i in range(sides + 1)]
    verts = [[x, y, z] for y in (0.0, H) for x, z in [(0.0, 0.0), *arc]]
    sig = [-K * P, -0.5 * (1 + K) * P * 0.5, -P, 0, 0, 0]
    e, big = 0.01, R + 1

    def box(lo, hi):
        return f"{{box: {{min: {lo}, max: {hi}}}}}"

    return f"""
name: kirsch
gravity: [0, 0, 0]
materials:
  rock: {{density: 2500, young: {E}, poisson: {NU}}}
joints:
  default: {{kn: 1.0e11, ks: 1.0e11, friction: 40, cohesion: 1.0e10, tension: 1.0e10}}
blocks:
  - {{name: rock, polyhedron: {{vertices: {verts}}}, material: rock, zones: {{size: {SIZE}}}}}
insitu: {{stress: {sig}}}
boundary:
  velocity:
    - {{range: {box([-1, -1, -1], [big, big, big])}, components: [y]}}
    - {{range: {box([-e, -1, -1], [e, big, big])}, components: [x]}}
    - {{range: {box([-1, -1, -e], [big, big, e])}, components: [z]}}
  stress:
    - {{range: {box([-1, -1, -1], [big, big, big])}, tensor: {sig}}}
stages:
  - name: excavate
    excavate: [{{cylinder: {{start: [0, -1, 0], end: [0, {H + 1}, 0], radius: {A},
                             sides: 32}}}}]
    solve: {{ratio: 2.0e-3, max_steps: 20000}}
solve: {{damping: local, mass_scaling: true}}
"""


BANDS = ((1.5, 2.0), (2.0, R))  # radial bands (of a) of the asserted zone stresses


def measured(sim, K: float):
    """The wall's radial displacement at the springline and the crown, each ``(measured,
    closed form)``, and the zones' radial and hoop stress errors averaged by band along both
    axes, of p: ``{(lo, hi, theta): (srr, stt, zones)}``."""
    sx, sz = -K * P, -P
    wall, zones = [], []
    for b in sim.state.grids.bodies:
        if not b.active:  # the excavated core
            continue
        x0 = b.nodes0
        r, th = np.hypot(x0[:, 0], x0[:, 2]), np.arctan2(x0[:, 2], x0[:, 0])
        u = b.nodes - x0
        at = r < A + 1e-9
        ur = u[at, 0] * np.cos(th[at]) + u[at, 2] * np.sin(th[at])
        wall.append(np.c_[th[at], ur, ring(sx, sz, A, R, G, NU, r[at], th[at])[3]])
        c = x0[b.tets].mean(axis=1)
        rc, tc = np.hypot(c[:, 0], c[:, 2]), np.arctan2(c[:, 2], c[:, 0])
        cs, sn, s = np.cos(tc), np.sin(tc), b.stress  # xx yy zz xy yz zx
        srr = s[:, 0] * cs**2 + s[:, 2] * sn**2 + 2 * s[:, 5] * cs * sn
        stt = s[:, 0] * sn**2 + s[:, 2] * cs**2 - 2 * s[:, 5] * cs * sn
        exact = ring(sx, sz, A, R, G, NU, rc, tc)
        zones.append(np.c_[rc, tc, srr - exact[0], stt - exact[1]])
    wall, zones = np.vstack(wall), np.vstack(zones)
    at_wall = {}
    for th in (0.0, math.pi / 2):  # springline and crown gridpoints
        k = np.argmin(np.abs(wall[:, 0] - th))
        assert abs(wall[k, 0] - th) < 1e-9
        at_wall[th] = (wall[k, 1], wall[k, 2])
    bands = {}
    for lo, hi in BANDS:
        for th in (0.0, math.pi / 2):
            band = (zones[:, 0] >= lo * A) & (zones[:, 0] < hi) & (np.abs(zones[:, 1] - th) < 0.15)
            err = zones[band, 2:].mean(axis=0) / P
            bands[(lo, hi, th)] = (err[0], err[1], int(band.sum()))
    return at_wall, bands


@pytest.mark.parametrize("K", [1.0, 0.5])
def test_tunnel_in_elastic_rock_against_kirsch(K):
    sim = Simulation(parse_scene(scene(K)), MPI.COMM_SELF, output=False)
    assert sim.run()["ratio"] <= 2.0e-3
    scale = P * A / (2 * G)
    at_wall, bands = measured(sim, K)
    for th, (got, exact) in at_wall.items():
        assert abs(got - exact) < 0.10 * scale, (th, got, exact)
    for key, (srr, stt, n) in bands.items():
        assert n > 20
        assert abs(srr) < 0.05 and abs(stt) < 0.05, (key, srr, stt)
