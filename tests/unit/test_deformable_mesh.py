"""Zoning of convex blocks (pdem.deformable.mesh): exact partition, orientation, conformity,
determinism, the edge bound, a zone-count bound and a shape-quality floor, on boxes, a bar, a
thin slab, prisms, a hull and pieces cut by tunnel and joint planes.

The zone counts and floors are the clipped lattice's (measured values in the comments; the
cone + bisection mesher it replaced gave the counts and angles in brackets, which fail the
bounds on the elongated, thin and cut blocks)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pdem.deformable.mesh import SNAP, min_dihedral_angles, signed_volumes, tetrahedralise
from pdem.geometry import box, from_vertices, prism
from pdem.geometry.cutting import clip_below


def _hull():
    # 24 points on an ellipsoid: an irregular convex block with faces of mixed sizes
    d = np.random.default_rng(7).normal(size=(24, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return from_vertices(d * [1.0, 0.7, 0.5])


_HEX = [[np.cos(a), np.sin(a), 0.0] for a in np.linspace(0.0, 2 * np.pi, 7)[:-1]]


def _ring_piece():
    """A piece of the quarter-Kirsch model (tests/verification/test_deformable_kirsch.py): the
    0.3 m slice of the quarter disc R = 3 (16-sided arc) beyond one face of the tunnel."""
    arc = [[3 * math.cos(t), 0.0, 3 * math.sin(t)] for t in np.linspace(0, math.pi / 2, 17)]
    n = np.array([math.cos(math.pi / 5), 0.0, math.sin(math.pi / 5)])
    return clip_below(prism([[0.0, 0.0, 0.0], *arc], [0.0, 0.3, 0.0]), -n, -1.0)


def _jointed_piece():
    """A 3 x 2 x 2.5 box cut by one plane of each of two joint sets (dip/dip direction 35/70
    and 80/200, tests/verification/test_rock_mass.py): an oblique wedge."""
    def normal(dip, dd):
        dip, dd = math.radians(dip), math.radians(dd)
        return np.array([math.sin(dip) * math.sin(dd), math.sin(dip) * math.cos(dd),
                         math.cos(dip)])
    p = clip_below(box([0, 0, 0], [3, 2, 2.5]), normal(35, 70), normal(35, 70) @ [1.1, 0.9, 1.3])
    return clip_below(p, -normal(80, 200), -normal(80, 200) @ [1.6, 1.2, 0.4])


# (block, zone size, minimum dihedral angle floor in degrees, most zones)
CASES = {
    "box": (lambda: box([0, 0, 0], [1, 1, 1]), 0.25, 40.0, 1400),  # 45.0, 1296 [45.0, 1536]
    "column": (lambda: box([0, 0, 0], [0.5, 0.5, 1.5]), 0.25, 40.0, 550),  # 45.0, 486 [14.8, 1560]
    "bar": (lambda: box([0, 0, 0], [0.1, 0.1, 2.0]), 0.1, 33.0, 800),  # 35.9, 696 [2.6, 13648]
    "column10": (lambda: box([0, 0, 0], [1, 1, 10]), 0.25, 40.0, 13000),  # 43.5, 12312 [5.7, 72944]
    "slab": (lambda: box([0, 0, 0], [2, 2, 0.05]), 0.5, 18.0, 1300),  # 19.3, 1176 [1.4, 1232]
    "prism": (lambda: prism(_HEX, [0.2, 0.1, 1.0]), 0.3, 13.0, 4000),  # 15.0, 3592 [20.2, 4166]
    "hull": (_hull, 0.3, 2.0, 2900),  # 2.7, 2609 [2.0, 2748] (small hull faces)
    "ring": (_ring_piece, 0.3, 8.0, 3400),  # 14.4, 3083 [1.35, 10784]
    "jointed": (_jointed_piece, 0.3, 13.0, 6500),  # 15.0, 5920 [0.65, 9623]
}


@pytest.fixture(scope="module", params=list(CASES))
def case(request):
    make, size, floor, most = CASES[request.param]
    poly = make()
    return request.param, poly, size, (floor, most), tetrahedralise(poly, size)


def test_volumes_partition_the_block(case):
    _, poly, _, _, m = case
    v = signed_volumes(m.nodes, m.tets)
    assert v.min() > 0.0  # positively oriented, none degenerate
    assert abs(v.sum() - poly.volume) <= 1e-12 * poly.volume


def test_edges_respect_size(case):
    """The lattice spacing is at most ``size / sqrt(2)``: blocks that lie on the lattice
    (boxes) keep the Kuhn tets' edges, at most a box diagonal ``sqrt(3 / 2) size``; no edge
    is longer than a box diagonal with both ends snapped the most (``+ 4 SNAP size /
    sqrt(2)``)."""
    name, poly, size, _, m = case
    x = m.nodes[m.tets]
    longest = max(np.linalg.norm(x[:, a] - x[:, b], axis=1).max()
                  for a in range(4) for b in range(a + 1, 4))
    print(f"longest edge {longest / size:.3f} size")
    on_lattice = name in ("box", "column", "bar", "column10", "slab")
    bound = math.sqrt(1.5) + (0.0 if on_lattice else 4 * SNAP / math.sqrt(2))
    assert longest <= bound * size * (1 + 1e-12)


def test_block_vertices_come_first_and_exact(case):
    _, poly, _, _, m = case
    assert np.array_equal(m.nodes[:poly.n_vertices], poly.vertices)


def test_nodes_are_unique_and_all_used(case):
    _, _, _, _, m = case
    assert len(np.unique(m.nodes, axis=0)) == len(m.nodes)
    assert np.array_equal(np.unique(m.tets), np.arange(len(m.nodes)))


def test_conforming_closed_surface(case):
    """Every interior tet face is shared by exactly two tets with opposite orientation, the
    boundary triangles' area vectors sum to zero and each lies on the face it is tagged with."""
    _, poly, _, _, m = case
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    tri = m.tets[:, local].reshape(-1, 3)
    _, count = np.unique(np.sort(tri, axis=1), axis=0, return_counts=True)
    assert count.max() == 2
    assert (count == 1).sum() == len(m.surface)
    x = m.nodes[m.surface]
    area_vec = 0.5 * np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    assert np.abs(area_vec.sum(axis=0)).max() < 1e-12 * np.abs(area_vec).sum()
    # tagged face: outward normal matches and the triangle lies in its plane
    n = np.asarray(poly.normals)[m.surface_face]
    unit = area_vec / np.linalg.norm(area_vec, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", unit, n).min() > 1 - 1e-9
    off = np.asarray(poly.offsets)[m.surface_face]
    assert np.abs(np.einsum("kij,kj->ki", x, n) - off[:, None]).max() < 1e-12 * poly.radius()
    # face areas per block face equal the face's area
    per_face = np.bincount(m.surface_face, np.linalg.norm(area_vec, axis=1), poly.n_faces)
    assert np.allclose(per_face, poly.face_areas(), rtol=1e-12)
    # surface flag: exactly the nodes of surface triangles, and those lie on the boundary
    dist = np.max(m.nodes @ np.asarray(poly.normals).T - np.asarray(poly.offsets), axis=1)
    assert np.all(np.abs(dist[m.on_surface]) < 1e-12 * poly.radius())
    assert np.all(dist[~m.on_surface] < -1e-9 * poly.radius())


def test_deterministic(case):
    name, _, size, _, m = case
    again = tetrahedralise(CASES[name][0](), size)
    assert again.surface_face.tobytes() == m.surface_face.tobytes()
    for a, b in ((m.nodes, again.nodes), (m.tets, again.tets), (m.surface, again.surface)):
        assert a.tobytes() == b.tobytes()


def test_quality_floor_and_zone_count(case):
    _, _, _, (floor, most), m = case
    angles = min_dihedral_angles(m.nodes, m.tets)
    print(f"{len(m.tets)} zones, min dihedral {angles.min():.2f} deg, "
          f"5th percentile {np.percentile(angles, 5):.2f}")
    assert angles.min() >= floor
    assert len(m.tets) <= most


def test_dihedral_of_regular_tet():
    """The quality measure itself: a regular tet's dihedral angle is arccos(1/3)."""
    x = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    t = np.array([[0, 1, 2, 3]])
    if signed_volumes(x, t)[0] < 0:
        t = t[:, [0, 2, 1, 3]]
    assert min_dihedral_angles(x, t)[0] == pytest.approx(np.degrees(np.arccos(1 / 3)), abs=1e-10)
